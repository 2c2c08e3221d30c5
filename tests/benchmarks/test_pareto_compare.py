"""Two speed-vs-accuracy results side by side (issue 17), and the axial-shortening copy of the
study."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest
from support import DATA

from flexctrl.analysis.pareto_compare import (
    case_table,
    compare,
    main,
    markdown,
    merge,
    plot,
    read_pareto,
)
from flexctrl.errors import SpecError
from flexctrl.study.executors import speed_vs_accuracy_executor as study

COLUMNS = [
    "scene",
    "method",
    "model",
    "integrator",
    "runs_ok",
    "runs_failed",
    "wall_per_sim_s",
    "tip_error_rms",
    "tip_error_rms_worst",
    "tip_error_max_worst",
    "n_states",
    "omega_max",
    "step_s",
    "pareto",
]


def _write(folder: Path, rows: list[tuple]) -> Path:
    folder.mkdir(parents=True)
    with open(folder / "pareto.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for scene, method, ok, failed, cost, rms, front in rows:
            w.writerow(
                [
                    scene,
                    method,
                    method.split("/")[0],
                    method.split("/")[1],
                    ok,
                    failed,
                    repr(cost),
                    repr(rms),
                    repr(2 * rms),
                    repr(3 * rms),
                    6,
                    100.0,
                    1e-3,
                    front,
                ]
            )
    return folder


@pytest.fixture
def pair(tmp_path):
    old = _write(
        tmp_path / "old",
        [
            ("bb", "rigid/rk4@1ms", 4, 0, 0.01, 2e-3, True),
            ("bb", "amm:2/rk4@1ms", 4, 0, 0.02, 3e-3, False),
            ("bb", "amm:3/rk4@1ms", 0, 4, math.nan, math.nan, False),
        ],
    )
    new = _write(
        tmp_path / "new",
        [
            ("bb", "rigid/rk4@1ms", 4, 0, 0.011, 2e-3, True),
            ("bb", "amm:2/rk4@1ms", 4, 0, 0.03, 1e-4, True),
            ("bb", "amm:3/rk4@1ms", 0, 4, math.nan, math.nan, False),
            ("bb", "fem:2/rk4@stable", 4, 0, 0.1, 1e-5, True),
        ],
    )
    return old, new


def test_compare_pairs_rows_and_names_what_joined_the_front(pair):
    rows = compare(read_pareto(pair[0]), read_pareto(pair[1] / "pareto.csv"))
    by = {r["method"]: r for r in rows}
    assert [r["method"] for r in rows] == [
        "rigid/rk4@1ms",
        "amm:2/rk4@1ms",
        "amm:3/rk4@1ms",
        "fem:2/rk4@stable",
    ]
    assert by["amm:2/rk4@1ms"]["front"] == "joined" and by["rigid/rk4@1ms"]["front"] == ""
    assert by["fem:2/rk4@stable"]["old"] is None and by["fem:2/rk4@stable"]["front"] == "joined"
    assert (
        by["amm:2/rk4@1ms"]["old"]["tip_error_rms"] == 3e-3
        and by["amm:2/rk4@1ms"]["new"]["tip_error_rms"] == 1e-4
    )


def test_markdown_gives_both_sides_in_mm_and_a_left_front(pair):
    rows = compare(read_pareto(pair[1]), read_pareto(pair[0]))  # swapped: amm:2 leaves the front
    text = markdown(rows, ("on", "off"))
    line = next(ln for ln in text.splitlines() if ln.startswith("| `amm:2/rk4@1ms`"))
    assert "| 0.1 / 3 |" in line and "| 0.03 / 0.02 |" in line and "yes / no (left)" in line
    failed = next(ln for ln in text.splitlines() if ln.startswith("| `amm:3/rk4@1ms`"))
    assert "| - / - |" in failed and "| 4 / 4 |" in failed
    assert "s per sim. s, on / off" in text and "#### bb" in text


def test_merge_replaces_a_rerun_scene_and_drops_the_over_all_rows(tmp_path):
    full = read_pareto(
        _write(
            tmp_path / "full",
            [
                ("bb", "rigid/rk4@1ms", 4, 0, 0.01, 2e-3, True),
                ("cl", "rigid/rk4@1ms", 0, 4, math.nan, math.nan, False),
                ("all scenes", "rigid/rk4@1ms", 4, 4, 0.01, 2e-3, False),
            ],
        )
    )
    rerun = read_pareto(_write(tmp_path / "cl", [("cl", "rigid/rk4@1ms", 4, 0, 0.02, 0.3, True)]))
    rows = merge(full, rerun)
    assert [(r["scene"], r["runs_ok"]) for r in rows] == [("bb", 4), ("cl", 4)]
    assert merge(full) == full


def test_case_table_shows_each_payload_on_both_sides(tmp_path):
    for side, values in (("off", (1e-3, 2e-3)), ("on", (3e-3, 0.5e-3))):
        (tmp_path / side).mkdir()
        with open(tmp_path / side / "results.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(
                ["scene", "payload", "q1", "q2", "q3", "scene.method", "status", "tip_error_rms"]
            )
            w.writerow(["bb", 0.0, 0, 0, 0, "amm:2/rk4@1ms", "ok", values[0]])
            w.writerow(["bb", 2.0, 0, 90, -45, "amm:2/rk4@1ms", "ok", values[1]])
            w.writerow(["bb", 2.0, 0, 90, -45, "amm:3/rk4@1ms", "failed", ""])
    text = case_table(
        [tmp_path / "off"],
        [tmp_path / "on"],
        "bb",
        ["amm:2/rk4@1ms", "amm:3/rk4@1ms"],
        ("off", "on"),
    )
    assert "| 0 | 0, 0, 0 | 1 / 3 | - / - |" in text
    assert "| 2 | 0, 90, -45 | 2 / 0.5 | failed / failed |" in text


def test_plot_and_command_line(pair, tmp_path, capsys):
    path = plot(
        compare(read_pareto(pair[0]), read_pareto(pair[1])), tmp_path / "c.png", ("off", "on")
    )
    assert path.stat().st_size > 10_000
    assert main(["--old", str(pair[0]), "--new", str(pair[1]), "--labels", "off", "on"]) == 0
    assert "| `amm:2/rk4@1ms` |" in capsys.readouterr().out
    assert main(["--old", str(pair[0]), "--new", str(tmp_path / "missing")]) == 2
    assert "no pareto.csv" in capsys.readouterr().err


# -- the study copy with the effect on ------------------------------------------------


def _run_settings(study_file: str, method: str, scene: str, *overrides: str) -> dict:
    from flexctrl.study.study_file import load_study

    spec = load_study(DATA / "studies" / study_file, list(overrides))
    return next(
        r.settings
        for r in spec.runs
        if Path(r.settings["scene"]).name == scene
        and f'scene.method="{method}"' in r.settings["overrides"]
    )


@pytest.mark.parametrize("scene", ["bangbang.toml", "move_joint1_30deg.toml"])
def test_shortening_study_switches_the_plant_and_the_shipped_one_does_not(scene):
    from flexctrl.scenes.arm_setup import scene_arm

    for study_file, expected in (
        ("speed_vs_accuracy_shortening.toml", True),
        ("speed_vs_accuracy.toml", None),
    ):
        plan = study.plan_from_settings(_run_settings(study_file, "amm:2/rk4@1ms", scene))
        plant = study._plant_scene(study._scene(study._plan_scene(plan)))
        assert plant.axial_shortening is expected
        assert scene_arm(plant).axial_shortening is expected


def test_shortening_reaches_the_model_and_moves_the_tip():
    base = _run_settings("speed_vs_accuracy.toml", "amm:1/rk4@1ms", "bangbang.toml")
    runs = {}
    for flag in ("false", "true"):
        settings = dict(
            base,
            overrides=[
                *[o for o in base["overrides"] if not o.startswith("scene.horizon")],
                "scene.horizon=0.3",
                f"scene.axial_shortening={flag}",
            ],
        )
        plan = study.plan_from_settings(settings)
        run, stepper = study.simulate_method(plan, plan.method)
        assert stepper.model.info["axial_shortening"] is (flag == "true")
        runs[flag] = run
    from flexctrl.sim.tip_error import tip_error

    e = tip_error(runs["true"].time, runs["true"].tip, runs["false"].time, runs["false"].tip)
    assert e.max > 1e-6  # the second-order kinematics change a 0.3 s bang-bang's tip path (m)


def test_a_bad_shortening_value_names_the_key():
    settings = _run_settings("speed_vs_accuracy.toml", "amm:2/rk4@1ms", "bangbang.toml")
    settings = dict(settings, overrides=[*settings["overrides"], 'scene.axial_shortening="yes"'])
    with pytest.raises(SpecError, match=r"axial_shortening.*'yes'.*true or false"):
        study.check_settings(settings)


def test_a_controller_sample_time_off_the_comparison_grid_is_refused_before_the_study_runs():
    settings = _run_settings("speed_vs_accuracy.toml", "amm:2/rk4@1ms", "move_joint1_30deg.toml")
    study.check_settings(settings)  # the shipped study pins 10 ms
    bad = dict(
        settings,
        overrides=[o for o in settings["overrides"] if not o.startswith("controller.sample_time")]
        + ["controller.sample_time=0.0075"],
    )
    with pytest.raises(
        SpecError, match=r"lqg.toml.*sample_time.*0.0075.*whole number of the 0.001 s"
    ):
        study.check_settings(bad)
