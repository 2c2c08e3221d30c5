"""Fidelity choices shared across a study's runs (``[auto] share``): one choice per group, recorded.

With ``fidelity = "auto"`` every run of a study chooses its plant model alone
(:func:`flexctrl.scenes.auto_closed_loop.choose_closed_loop_fidelity`): a walk over the rungs and
a reference run per run, which costs several times the run itself.  A study whose
axes hold values the user knows do not change the choice declares them::

    [auto]
    share = ["configuration"]   # grid axes; one choice per combination of the OTHER axes

Runs then fall into groups that differ only in the shared axes.  The group's
*representative* is its first run in grid order (every shared axis at its first
value); the choice is made once, on the representative's scene, and every member
runs with the chosen rung (its RK4 step recomputed for the member's own model by the
same rule, :func:`flexctrl.sim.rk4.rk4_step`).  The representative's settings travel in
each member's settings (``choice_from``), so any worker makes the same choice and
the table does not depend on the order runs ran in.  A group whose choice fails
(no rung meets the tolerance) fails all its runs with the same error, chosen once.

Members do not have an error estimate of their own: the table's ``estimated_error``
and ``reference_error`` are the representative's, ``choice_shared`` is 1 for a
member and 0 for the representative, and ``fidelity_choices.json`` in the study's
folder lists every group, its representative, its choice and its members
(:func:`write_choices`).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

#: File in the study's folder that lists the shared choices.
CHOICES_FILE = "fidelity_choices.json"


def representative_combo(
    combo: Sequence[Any], axis_keys: Sequence[str], share: Sequence[str], first: dict[str, Any]
) -> tuple[Any, ...]:
    """The grid point of ``combo``'s group representative: every shared axis at its first value."""
    return tuple(first[key] if key in share else value for key, value in zip(axis_keys, combo))


def choice_settings(settings: dict[str, Any]) -> dict[str, Any]:
    """What of a run's settings makes its choice (the representative's, carried by every member)."""
    return {
        k: settings[k]
        for k in (
            "scene",
            "model",
            "controller",
            "payload",
            "q0_deg",
            "fidelity",
            "overrides",
            "seed",
            "digests",
        )
        if k in settings
    }


def write_choices(directory: str | Path, runs, records: dict[str, dict[str, Any]]) -> Path | None:
    """Write :data:`CHOICES_FILE`: per group its representative, choice and members; None without
    shared choices.

    ``runs`` are the study's :class:`~flexctrl.study.plan.RunSpec`; ``records`` the
    stored run records by run id (their ``metrics`` hold ``chosen_modes``,
    ``chosen_dt``, ``estimated_error``, ``reference_error``, ``choice_time_s``).
    """
    groups: dict[str, dict[str, Any]] = {}
    for run in runs:
        settings = run.settings
        rep = settings.get("choice_from")
        if rep is None:
            continue
        key = json.dumps(rep, sort_keys=True)
        group = groups.setdefault(key, {"representative": None, "choice": None, "members": []})
        record = records.get(run.run_id) or {}
        metrics = record.get("metrics") or {}
        entry = {
            "run_id": run.run_id,
            **dict(run.coords),
            "status": record.get("status", "pending"),
        }
        if "chosen_modes" in metrics:
            entry["chosen_dt_s"] = metrics.get("chosen_dt")
        if record.get("status") == "failed":
            entry["error"] = record.get("error")
        group["members"].append(entry)
        if metrics.get("choice_shared") == 0.0 or choice_settings(settings) == rep:
            group["representative"] = entry["run_id"]
            if "chosen_modes" in metrics:
                modes = int(metrics["chosen_modes"])
                group["choice"] = {
                    "fidelity": "rigid" if modes == 0 else f"amm:{modes}",
                    "estimated_error_m": metrics.get("estimated_error"),
                    "reference_error_m": metrics.get("reference_error"),
                    "choice_time_s": metrics.get("choice_time_s"),
                }
            elif record.get("status") == "failed":
                group["choice"] = {"fidelity": None, "error": record.get("error")}
    if not groups:
        return None
    path = Path(directory) / CHOICES_FILE
    document = {
        "note": "fidelity = 'auto' with [auto] share: one choice per group, made on its "
        "representative "
        "(first run in grid order) and used by every member "
        "(docs/explanation/automatic-fidelity.md)",
        "groups": list(groups.values()),
    }
    path.write_text(json.dumps(document, indent=2, default=str) + "\n")
    return path
