"""Study files, grid expansion, run ids, the result store, failures and the report.

Runs use the ``_selftest`` executor (a damped oscillator in numpy, shipped in
flexctrl/study/executors.py) in this process (``workers=0``) to stay fast; the
process pool, Dask and kill/resume are in ``test_study_runs.py``.
"""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from support import DATA as SHIPPED
from support import ROOT

from flexctrl import cli
from flexctrl.errors import SpecError
from flexctrl.spec.overrides import parse_value
from flexctrl.study import RunOutput, load_study, register_executor, run_study
from flexctrl.study.executors.selftest_executor import _selftest_build
from flexctrl.study.executors.selftest_executor import execute as run_selftest
from flexctrl.study.hashing import canonical_json, derive_seed, identity, short_hash
from flexctrl.study.plan import toml_literal
from flexctrl.study.progress import Progress
from flexctrl.study.run_execution import execute_run
from flexctrl.study.store import Table

TEST_DATA = ROOT / "tests" / "data"
VOLATILE = ("wall_time_s", "peak_memory_mb", "bytes_written", "worker")


def variant(
    study: Path, name: str, replace: dict[str, str] | None = None, append: str = ""
) -> Path:
    """A copy of the example study next to it, with text replaced and/or appended."""
    text = study.read_text()
    for old, new in (replace or {}).items():
        assert old in text, old
        text = text.replace(old, new)
    path = study.with_name(name)
    path.write_text(text + append)
    return path


def stable(table: Table) -> list[dict]:
    """Rows without the columns that depend on timing and on the worker."""
    return [{k: v for k, v in row.items() if k not in VOLATILE} for row in table.rows]


# -- grid and ids -----------------------------------------------------------------------------


def test_grid_is_the_cartesian_product_with_joint_axes_on_the_fixed_configuration(study):
    spec = load_study(study)
    assert len(spec.runs) == 2 * 2 * 3 * 2
    assert spec.columns == ("payload", "q2", "q3", "controller")
    coords = [run.coordinates for run in spec.runs]
    assert coords[0] == {"payload": 0.0, "q2": 0.0, "q3": -90.0, "controller": "soft"}
    assert coords[-1] == {"payload": 2.0, "q2": 90.0, "q3": 90.0, "controller": "stiff"}
    for run in spec.runs:
        s = run.settings
        assert s["q0_deg"] == [0.0, run.coordinates["q2"], run.coordinates["q3"]]
        assert s["payload"] == run.coordinates["payload"]
        assert (
            Path(s["controller"]).stem == run.coordinates["controller"]
            and Path(s["controller"]).is_absolute()
        )
        assert set(s["digests"]) == {"scene", "model", "controller"}
    assert len({run.run_id for run in spec.runs}) == len(spec.runs)


def test_run_ids_and_seeds_do_not_depend_on_axis_order(study):
    spec = load_study(study)
    shuffled = variant(
        study,
        "shuffled.toml",
        {
            "payload = [0.0, 2.0]\nq2 = [0, 90]\nq3 = [-90, 0, 90]\ncontroller = "
            '["controllers/soft.toml", "controllers/stiff.toml"]': "controller = "
            '["controllers/stiff.toml", '
            '"controllers/soft.toml"]\nq3 '
            "= [90, 0, -90]\npayload = [2, "
            "0]\nq2 = [90, 0]",
        },
    )
    other = load_study(shuffled)
    assert [r.run_id for r in other.runs] != [r.run_id for r in spec.runs]  # another order ...
    by_id = {r.run_id: r for r in spec.runs}
    assert set(by_id) == {r.run_id for r in other.runs}  # ... the same runs
    for run in other.runs:
        assert run.settings == by_id[run.run_id].settings
        assert run.coordinates == by_id[run.run_id].coordinates


def test_different_settings_give_different_ids_and_seeds(study):
    spec = load_study(study)
    reseeded = load_study(study, overrides=["seed=8"])
    assert not {r.run_id for r in spec.runs} & {r.run_id for r in reseeded.runs}
    assert [r.settings["seed"] for r in spec.runs] != [r.settings["seed"] for r in reseeded.runs]
    # each seed derives from the study seed and the run's settings without the seed
    run = spec.runs[5]
    settings = run.settings
    seed = settings.pop("seed")
    assert seed == derive_seed(7, short_hash(identity(settings, study.parent)))
    # editing a controller file changes the ids of its runs only
    soft = study.parent / "controllers" / "soft.toml"
    soft.write_text(soft.read_text().replace("0.02", "0.03"))
    edited = load_study(study)
    for before, after in zip(spec.runs, edited.runs):
        assert (before.run_id == after.run_id) == (before.coordinates["controller"] == "stiff")


def test_canonical_json_and_toml_literals():
    assert canonical_json({"b": 1, "a": [-0.0, 2.5]}) == '{"a":[0.0,2.5],"b":1}'
    assert short_hash({"a": 1, "b": 2}) == short_hash({"b": 2, "a": 1})
    with pytest.raises(ValueError):
        canonical_json({"a": float("nan")})
    for value in (
        1,
        2.5,
        -3e-7,
        0.1 + 0.2,
        "amm:2",
        'say "hi"',
        True,
        [0, 90.5, "x"],
        {"k": [1, 2]},
    ):
        assert parse_value(toml_literal(value)) == value


def test_overrides_and_replicates_become_axes_with_their_own_seeds(study):
    path = variant(
        study,
        "over.toml",
        {"seed = 7": "seed = 7\nreplicates = 2"},
        '\n[set]\n"scene.noise_std" = 2e-4\n',
    )
    path.write_text(path.read_text().replace("[grid]\n", '[grid]\n"scene.duration" = [0.5, 1.0]\n'))
    spec = load_study(path)
    assert len(spec.runs) == 24 * 2 * 2
    assert spec.columns == ("scene.duration", "payload", "q2", "q3", "controller", "replicate")
    run = spec.runs[0].settings
    assert run["overrides"] == ["scene.duration=0.5", "scene.noise_std=0.0002"]
    seeds = {(r.settings["replicate"], r.settings["seed"]) for r in spec.runs}
    assert len({s for _, s in seeds}) == len(spec.runs)


# -- broken study files ------------------------------------------------------------------------

BROKEN = [
    (
        "unknown_controller",
        {'"controllers/stiff.toml"]': '"controllers/stif.toml"]'},
        "",
        "grid.controller[2]",
        "stiff.toml",
    ),
    (
        "misspelt_axis",
        {"payload = [0.0, 2.0]": "paylaod = [0.0, 2.0]"},
        "",
        "grid.paylaod",
        "did you mean 'payload'",
    ),
    ("misspelt_top_key", {"seed = 7": "seeed = 7"}, "", "seeed", "did you mean 'seed'"),
    (
        "negative_payload",
        {"payload = [0.0, 2.0]": "payload = [0.0, -2.0]"},
        "",
        "grid.payload[2]",
        ">= 0",
    ),
    ("empty_axis", {"payload = [0.0, 2.0]": "payload = []"}, "", "grid.payload", "empty"),
    (
        "unknown_executor",
        {'executor = "_selftest"': 'executor = "_selftset"'},
        "",
        "executor",
        "did you mean '_selftest'",
    ),
    (
        "short_configuration",
        {"configuration = [0, 0, 0]": "configuration = [0, 0]"},
        "",
        "configuration",
        "3 joints",
    ),
    (
        "misspelt_override_target",
        {},
        '\n[set]\n"sceen.duration" = 2.0\n',
        "set.sceen.duration",
        "did you mean 'scene.duration'",
    ),
    ("misspelt_scene_key", {}, '\n[set]\n"scene.duraton" = 2.0\n', "duraton", "ring.toml"),
    (
        "unknown_map_axis",
        {'map_axes = ["q2", "q3"]': 'map_axes = ["q2", "q9"]'},
        "",
        "report.map_axes",
        "q9",
    ),
    (
        "axis_and_fixed",
        {"[grid]\n": "[grid]\nconfiguration = [[0, 0, 0]]\n"},
        "",
        "grid.configuration",
        "both",
    ),
]


@pytest.mark.parametrize("case, replace, append, key, detail", BROKEN, ids=[c[0] for c in BROKEN])
def test_broken_study_is_refused_before_any_run(
    study, tmp_path, capsys, case, replace, append, key, detail
):
    path = variant(study, f"{case}.toml", replace, append)
    out = tmp_path / "out"
    assert cli.main(["study", str(path), "--out", str(out), "--workers", "0"]) == 2
    message = capsys.readouterr().err
    assert f"{case}.toml" in message and f"key '{key}'" in message and detail in message, message
    assert "\n" not in message.strip()
    assert not out.exists()  # nothing was created, let alone run


def test_resume_needs_a_study_and_out_must_hold_the_same_study(study, tmp_path):
    spec = load_study(study)
    with pytest.raises(SpecError, match="nothing to resume"):
        run_study(spec, tmp_path / "empty", resume=True, workers=0, progress="none")
    other = load_study(
        variant(study, "renamed.toml", {'name = "selftest"': 'name = "other"'}),
        overrides=["grid.payload=[0.0]", "grid.q3=[0]"],
    )
    run_study(other, tmp_path / "out", workers=0, progress="none", report=False)
    with pytest.raises(SpecError, match="holds the results of study 'other'"):
        run_study(spec, tmp_path / "out", workers=0, progress="none")


# -- running, records, failures, the report ----------------------------------------------------


def test_same_study_gives_the_same_table_and_a_rerun_skips_recorded_runs(study, tmp_path):
    spec = load_study(study)
    first = run_study(spec, tmp_path / "a", workers=0, progress="none", report=False)
    second = run_study(spec, tmp_path / "b", workers=0, progress="none", report=False)
    assert first.counts["ok"] == 24 and stable(first.table()) == stable(second.table())
    again = run_study(spec, tmp_path / "a", workers=0, progress="none", report=False)
    assert again.counts["ran"] == 0 and again.counts["skipped"] == 24
    assert stable(again.table()) == stable(first.table())
    study_json = json.loads((tmp_path / "a" / "study.json").read_text())
    assert len(study_json["sessions"]) == 2 and study_json["end"]
    assert {"flexctrl", "numpy", "scipy", "casadi", "control", "osqp"} <= set(
        study_json["versions"]
    )
    assert study_json["machine"]["cpu_count"] >= 1 and study_json["study"]["name"] == "selftest"


def test_records_are_plain_data_with_decimated_trajectories(study, tmp_path):
    spec = load_study(study, overrides=["grid.q3=[0]"])
    result = run_study(spec, tmp_path / "out", workers=0, progress="none", report=False)
    table = result.table()
    assert table.columns[:6] == ["run_id", "payload", "q2", "q3", "controller", "seed"]
    assert {
        "tip_residual_rms",
        "tip_peak",
        "settling_time",
        "frequency_hz",
        "status",
        "error",
        "wall_time_s",
        "peak_memory_mb",
        "bytes_written",
    } <= set(table.columns)
    for row in table.rows:
        record = json.loads((tmp_path / "out" / "runs" / f"{row['run_id']}.json").read_text())
        assert record["metrics"]["tip_peak"] == row["tip_peak"] and record["status"] == "ok"
        with np.load(tmp_path / "out" / "runs" / record["trajectories"], allow_pickle=False) as npz:
            assert npz["t"].shape == (101,)  # 501 samples, every 5th kept
            assert npz["t"][1] == pytest.approx(5 * 0.002)
        npz_size = (tmp_path / "out" / "runs" / record["trajectories"]).stat().st_size
        json_size = (tmp_path / "out" / "runs" / f"{row['run_id']}.json").stat().st_size
        assert row["bytes_written"] == npz_size + json_size
        assert row["peak_memory_mb"] > 10
    # the physics of the oscillator: a payload lowers the frequency, the stiff controller damps
    # faster
    rows = {(r["payload"], r["q2"], r["controller"]): r for r in table.rows}
    assert rows[(2.0, 0.0, "soft")]["frequency_hz"] < rows[(0.0, 0.0, "soft")]["frequency_hz"]
    assert (
        rows[(0.0, 0.0, "stiff")]["tip_residual_rms"] < rows[(0.0, 0.0, "soft")]["tip_residual_rms"]
    )
    assert not list((tmp_path / "out").rglob("*.tmp"))


def test_failing_runs_are_recorded_the_study_goes_on_and_the_report_lists_them(study, tmp_path):
    path = variant(
        study,
        "failing.toml",
        {
            '"controllers/stiff.toml"]': '"controllers/stiff.toml", "controllers/unstable.toml"]',
            "q3 = [-90, 0, 90]": "q3 = [0]",
        },
        '\n[set]\n"scene.fail_payload" = 2.0\n',
    )
    spec = load_study(path)
    result = run_study(spec, tmp_path / "out", workers=0, progress="none")
    table = result.table()
    failed = [r for r in table.rows if r["status"] == "failed"]
    ok = [r for r in table.rows if r["status"] == "ok"]
    # payload 2 fails for every controller; payload 0 diverges with the unstable controller
    assert len(table) == 12 and len(failed) == 8 and len(ok) == 4
    for row in failed:
        if row["payload"] == 2.0:
            assert row["error"].startswith(
                "RuntimeError: selftest failure requested for payload 2 kg"
            )
        else:
            assert row["controller"] == "unstable" and row["error"].startswith(
                "SimulationError: diverged"
            )
        assert row["tip_residual_rms"] is None
    report = result.report.read_text()
    section = report.split("## Failed runs")[1]
    assert "8 run(s) failed" in section
    for row in failed:
        assert row["run_id"] in section
    assert "diverged" in section and "selftest failure requested" in section


def test_report_is_redrawn_from_the_result_folder_alone(study, tmp_path, capsys):
    out = tmp_path / "out"
    assert cli.main(["study", str(study), "--out", str(out), "--workers", "0", "--quiet"]) == 0
    original = (out / "report.md").read_text()
    figures = sorted(p.name for p in (out / "figures").glob("*.png"))
    assert {"map_tip_residual_rms.png", "ranking_tip_residual_rms.png"} <= set(figures)
    assert sum(name.startswith("worst_") for name in figures) == 2
    # remove the report, the figures, the table, and every input file of the study
    (out / "report.md").unlink()
    shutil.rmtree(out / "figures")
    (out / "results.csv").unlink()
    shutil.rmtree(study.parent)
    shutil.rmtree(tmp_path / "models")
    capsys.readouterr()
    assert cli.main(["report", str(out)]) == 0
    assert (out / "report.md").read_text() == original
    assert sorted(p.name for p in (out / "figures").glob("*.png")) == figures
    for section in ("## Maps", "## Ranking", "## Worst cases", "## Timing", "## Failed runs"):
        assert section in original
    # options override the study's [report] table; an unknown metric is refused
    assert (
        cli.main(["report", str(out), "--metric", "tip_peak", "--map-axes", "payload", "q3"]) == 0
    )
    assert "map_tip_peak.png" in {p.name for p in (out / "figures").glob("*.png")}
    assert cli.main(["report", str(out), "--metric", "tip_rms"]) == 2
    assert "key '--metric'" in capsys.readouterr().err


# -- executors, cache, progress ---------------------------------------------------------------


def test_build_step_is_cached_per_worker(study):
    settings = load_study(study).runs[0].settings
    before = _selftest_build.cache_info()
    run_selftest(dict(settings))
    run_selftest(dict(settings, payload=2.0, q0_deg=[0.0, 90.0, 0.0]))
    after = _selftest_build.cache_info()
    assert after.misses - before.misses <= 1 and after.hits - before.hits >= 1


def _bad_executor(settings):
    return {"tip": 1.0}


def _nan_executor(settings):
    return RunOutput({"tip": float("nan")}, {"t": np.arange(3.0)})


def test_executor_outputs_are_checked():
    with pytest.raises(TypeError, match="real scalar"):
        RunOutput({"x": [1.0]})
    with pytest.raises(TypeError, match="1-D"):
        RunOutput({"x": 1.0}, {"y": np.zeros((2, 2))})
    register_executor("_test_bad", _bad_executor)
    register_executor("_test_nan", _nan_executor)
    bad = execute_run("_test_bad", {}, {})
    assert bad["status"] == "failed" and "expected a RunOutput" in bad["error"]
    nan = execute_run("_test_nan", {}, {"decimation": 2})
    assert nan["status"] == "failed" and "non-finite metric tip" in nan["error"]
    assert nan["trajectories"]["t"].tolist() == [0.0, 2.0]
    missing = execute_run("_test_nan", {}, {"metrics": ["rms"]})
    assert "returned no metric 'rms'" in missing["error"]


def _empty_executor(settings):
    return RunOutput({"tip": 1.0, "settle": float("nan")}, notes={"settle": "never settles"})


def test_a_metric_left_empty_with_a_reason_is_no_failure():
    register_executor("_test_empty", _empty_executor)
    out = execute_run("_test_empty", {}, {"metrics": ["tip", "settle"]})
    assert out["status"] == "ok" and np.isnan(out["metrics"]["settle"])
    assert "settle: never settles" in out["error"]


def test_progress_lines_count_runs_and_estimate_the_time_left():
    now = [0.0]
    stream = io.StringIO()
    bar = Progress(
        10, skipped=2, label="s", mode="lines", stream=stream, interval=5.0, clock=lambda: now[0]
    )
    for k in range(4):
        now[0] += 2.0
        bar.update(ok=k != 1)
    bar.close()
    lines = stream.getvalue().splitlines()
    assert lines[0] == "s: 0/10 runs done, 0 failed, 2 already recorded, elapsed 0:00, left ?"
    assert lines[1] == "s: 3/10 runs done, 1 failed, 2 already recorded, elapsed 0:06, left ~0:14"
    assert lines[-1] == "s: 4/10 runs done, 1 failed, 2 already recorded, elapsed 0:08, left ~0:12"
    quiet = io.StringIO()
    Progress(3, mode="none", stream=quiet).update(True)
    assert quiet.getvalue() == ""
    # a resume with nothing left says so once
    done = io.StringIO()
    Progress(0, skipped=5, label="s", mode="lines", stream=done).close()
    assert done.getvalue() == "s: nothing to run (5 already recorded)\n"


def test_quoted_dotted_axis_is_replaced_by_a_nested_override(study):
    path = variant(study, "dotted.toml", {"[grid]\n": '[grid]\n"scene.duration" = [1.0, 2.0]\n'})
    base = load_study(path)
    assert {a.key: a.values for a in base.axes}["scene.duration"] == (1.0, 2.0)
    replaced = load_study(path, ["grid.scene.duration=[3.0]"])
    assert {a.key: a.values for a in replaced.axes}["scene.duration"] == (3.0,)
    assert len(replaced.runs) == len(base.runs) // 2


def test_quoted_override_key_reaches_a_quoted_axis_beside_a_file_axis(root):
    """grid.scene (files) and grid."scene.method" cannot both nest; --set must still reach the
    latter."""
    path = SHIPPED / "studies" / "speed_vs_accuracy.toml"
    methods = ["amm:2/rk4@0.25ms", "amm:2+sched/rk4@1ms"]
    spec = load_study(
        path,
        [
            'grid.scene=["scenes/free_vibration.toml"]',
            f'grid."scene.method"={methods!r}'.replace("'", '"'),
        ],
    )
    axes = {a.key: a.values for a in spec.axes}
    assert axes["scene.method"] == tuple(methods)
    assert len(spec.runs) == 1 * 2 * 2 * 2  # scene x payload x configuration x method


def test_quoted_override_key_names_the_same_setting_as_the_nested_one(study):
    path = variant(study, "dotted2.toml", {"[grid]\n": '[grid]\n"scene.duration" = [1.0, 2.0]\n'})
    replaced = load_study(path, ['grid."scene.duration"=[3.0]'])
    assert {a.key: a.values for a in replaced.axes}["scene.duration"] == (3.0,)


def test_same_setting_spelt_quoted_and_nested_is_refused(study):
    text = (
        study.read_text().replace("[grid]\n", '[grid]\n"scene.duration" = [1.0]\n')
        + "\n[grid.scene]\nduration = [2.0]\n"
    )
    path = study.with_name("twice.toml")
    path.write_text(text)
    with pytest.raises(SpecError, match="given twice"):
        load_study(path)


def test_executors_without_a_model_need_no_model_key(root):
    spec = load_study(
        SHIPPED / "studies" / "baumgarte_sweep.toml",
        ["grid.scene.dt=[1e-3]", "grid.scene.baumgarte=[5.0]", "grid.scene.feedback=['explicit']"],
    )
    assert len(spec.runs) == 1 and spec.runs[0].settings["model"] is None


@pytest.mark.parametrize("workers", [0, 2])
def test_warnings_of_runs_are_recorded_summed_up_and_listed_in_the_report(study, tmp_path, workers):
    path = variant(study, "warning.toml", {"q3 = [-90, 0, 90]": "q3 = [0]"})
    path = variant(path, "warning.toml", append='\n[set]\n"scene.warn_payload" = 2.0\n')
    out = tmp_path / "out"
    result = run_study(load_study(path), out, workers=workers, progress="none")
    warned = [r for r in result.table().rows if r["payload"] == 2.0]
    quiet = [r for r in result.table().rows if r["payload"] != 2.0]
    assert warned and quiet
    line = "UserWarning: selftest warning requested for payload 2 kg (scene key warn_payload)"
    for row in warned:
        record = json.loads((out / "runs" / f"{row['run_id']}.json").read_text())
        assert record["status"] == "ok" and record["warnings"] == [line]
    for row in quiet:
        assert json.loads((out / "runs" / f"{row['run_id']}.json").read_text())["warnings"] == []
    assert result.warnings == [
        f"{len(warned)} run(s) warned (1 distinct warning(s); report.md lists each), the first: "
        + line
    ]
    section = result.report.read_text().split("## Warnings")[1]
    assert f"| {len(warned)} | " in section and line in section
