"""``[auto] share``: one fidelity choice per group of runs, on the group's first run, listed in
fidelity_choices.json.

Grid expansion and the choices file are checked here without simulating (the
``_selftest`` study); the closed-loop choice itself is the closed-loop scene tests'.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from flexctrl.errors import SpecError
from flexctrl.study import load_study
from flexctrl.study.shared_choice import CHOICES_FILE, choice_settings, write_choices


def with_share(study: Path, share: str) -> Path:
    path = study.with_name("shared.toml")
    path.write_text(
        study.read_text().replace("[trajectories]", f"[auto]\nshare = {share}\n\n[trajectories]")
    )
    return path


def test_each_run_carries_its_group_representative_the_first_in_grid_order(
    study,
):
    plain, spec = load_study(study), load_study(with_share(study, '["q2", "q3"]'))
    assert len(spec.runs) == len(plain.runs) == 24
    by_coords = {tuple(sorted(r.coordinates.items())): r for r in spec.runs}
    groups = {}
    for run in spec.runs:
        c = run.coordinates
        rep = by_coords[tuple(sorted({**c, "q2": 0.0, "q3": -90.0}.items()))]
        assert run.settings["choice_from"] == choice_settings(rep.settings)
        assert rep.index <= run.index
        groups.setdefault(json.dumps(run.settings["choice_from"], sort_keys=True), []).append(run)
    assert len(groups) == 2 * 2  # payload x controller: the shared axes q2, q3 do not split groups
    assert all(len(members) == 6 for members in groups.values())
    # the seeds stay those of the study without sharing (the share changes the run ids, not the
    # noise)
    assert [r.settings["seed"] for r in spec.runs] == [r.settings["seed"] for r in plain.runs]
    assert "choice_from" not in plain.runs[0].settings


def test_share_names_only_grid_axes(study):
    with pytest.raises(
        SpecError, match=r"auto.share.*'seed' is not allowed; allowed: payload, q2, q3, controller"
    ):
        load_study(with_share(study, '["seed"]'))


def test_choices_file_lists_groups_their_representative_choice_and_members(study, tmp_path):
    spec = load_study(with_share(study, '["q3"]'))
    records = {}
    for run in spec.runs:
        rep = run.settings["choice_from"] == choice_settings(run.settings)
        if run.coordinates["controller"] == "soft":
            records[run.run_id] = {
                "status": "ok",
                "metrics": {
                    "chosen_modes": 3.0,
                    "chosen_dt": 2.5e-4,
                    "estimated_error": 4e-5,
                    "reference_error": 2e-5,
                    "choice_time_s": 9.0 if rep else 0.0,
                    "choice_shared": 0.0 if rep else 1.0,
                },
            }
        else:
            records[run.run_id] = {
                "status": "failed",
                "error": "ToleranceUnreachable: no rung",
                "metrics": {},
            }
    path = write_choices(tmp_path, spec.runs, records)
    assert path == tmp_path / CHOICES_FILE
    groups = json.loads(path.read_text())["groups"]
    assert len(groups) == 2 * 2 * 2  # payload x q2 x controller
    for group in groups:
        assert (
            len(group["members"]) == 3 and group["representative"] == group["members"][0]["run_id"]
        )
        assert group["members"][0]["q3"] == -90.0
        if group["members"][0]["controller"] == "soft":
            assert (
                group["choice"]["fidelity"] == "amm:3"
                and group["choice"]["estimated_error_m"] == 4e-5
            )
        else:
            assert group["choice"] == {"fidelity": None, "error": "ToleranceUnreachable: no rung"}
    assert write_choices(tmp_path, load_study(study).runs, records) is None
