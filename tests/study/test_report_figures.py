"""The study report's figures and tables as a reader sees them: units, panels, best and ratio maps,
overlays.

Every figure the report writes is captured (``Figure.savefig`` wrapped) so its panels,
axis labels and scales are checked, not only the files' existence.  The closed-loop
study is two runs (PD and LQR at one pose, amm:1, 4 s), so the worst case of that cell
overlays both controllers; ``fc.compare`` of the same two runs from Python draws the
same panels.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure
from support import DATA as SHIPPED
from support import ROOT

import flexctrl as fc
from flexctrl import cli
from flexctrl.study import load_study, run_study
from flexctrl.study.column_units import display
from flexctrl.study.report import write_report

TEST_DATA = ROOT / "tests" / "data"


@pytest.fixture
def captured(monkeypatch) -> dict[str, Figure]:
    """File name -> the Figure saved to it, for every figure saved while the test runs."""
    figures: dict[str, Figure] = {}
    original = Figure.savefig

    def savefig(self, fname, *args, **kwargs):
        figures[Path(fname).name] = self
        return original(self, fname, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", savefig)
    return figures


@pytest.fixture
def selftest_out(tmp_path, root) -> Path:
    shutil.copytree(TEST_DATA, tmp_path / "tests" / "data")
    (tmp_path / "models").mkdir()
    shutil.copy(SHIPPED / "models" / "subedi3link.toml", tmp_path / "models")
    out = tmp_path / "out"
    run_study(
        load_study(tmp_path / "tests" / "data" / "study_selftest.toml"),
        out,
        workers=0,
        progress="none",
        report=False,
    )
    return out


def _panels(fig: Figure) -> list:
    """The axes a reader sees (colour bars have no x label and no title)."""
    return [ax for ax in fig.axes if ax.get_visible() and (ax.get_title() or ax.get_xlabel())]


def test_maps_best_and_ratio_maps_carry_units_and_one_panel_per_cell_group(selftest_out, captured):
    text = write_report(selftest_out).read_text()
    # 2 payloads x 2 controllers on the metric map; one best panel per payload; ratio: 2 x 2
    maps = _panels(captured["map_tip_residual_rms.png"])
    assert len(maps) == 4
    assert {ax.get_xlabel() for ax in maps} == {"q2 (deg)"} and {
        ax.get_ylabel() for ax in maps
    } == {"q3 (deg)"}
    assert {ax.get_title() for ax in maps} == {
        f"payload = {p} kg, controller = {c}" for p in (0, 2) for c in ("soft", "stiff")
    }
    colour_bars = [ax for ax in captured["map_tip_residual_rms.png"].axes if ax not in maps]
    assert [ax.get_ylabel() for ax in colour_bars] == ["tip residual RMS (mm)"]
    # the cells show mm: the panel's written values are the table's values (m) times 1000
    rows = [r for r in _table(selftest_out) if r["payload"] == 0.0 and r["controller"] == "soft"]
    written = sorted(float(t.get_text()) for t in maps[0].texts)
    np.testing.assert_allclose(
        written, sorted(1e3 * r["tip_residual_rms"] for r in rows), rtol=5e-3
    )
    best = _panels(captured["best_tip_residual_rms.png"])
    assert [ax.get_title() for ax in best] == ["payload = 0 kg", "payload = 2 kg"]
    assert all(len(ax.texts) == 6 for ax in best)  # every cell names its winner and value
    ratio = _panels(captured["ratio_tip_residual_rms.png"])
    assert len(ratio) == 4
    values = [float(t.get_text().lstrip("×")) for ax in ratio for t in ax.texts]
    assert min(values) == pytest.approx(1.0) and all(v >= 1.0 for v in values)
    assert (
        sum(1 for v in values if v == pytest.approx(1.0)) == 12
    )  # one best of two per cell: 2 payloads x 6 cells
    for header in (
        "| rank | controller | median tip residual RMS (mm) | min (mm) | max (mm) |",
        "| rank | run_id | payload (kg) | q2 (deg) | q3 (deg) | controller | tip residual RMS "
        "(mm) |",
        "### payload = 2 kg",
    ):
        assert header in text, header


def test_a_large_grid_is_drawn_without_text_in_its_cells_and_the_report_says_where_the_values_are(
    tmp_path, root, captured
):
    # 9 x 8 = 72 cells a panel: beyond TEXT_CELLS (64) names and values would overlap their
    # neighbours
    shutil.copytree(TEST_DATA, tmp_path / "tests" / "data")
    (tmp_path / "models").mkdir()
    shutil.copy(SHIPPED / "models" / "subedi3link.toml", tmp_path / "models")
    out = tmp_path / "out"
    grid = [
        "grid.payload=[2.0]",
        "grid.q2=[-120, -90, -60, -30, 0, 30, 60, 90, 120]",
        "grid.q3=[-105, -75, -45, -15, 15, 45, 75, 105]",
    ]
    run_study(
        load_study(tmp_path / "tests" / "data" / "study_selftest.toml", overrides=grid),
        out,
        workers=0,
        progress="none",
        report=False,
    )
    text = write_report(out).read_text()
    best = _panels(captured["best_tip_residual_rms.png"])
    assert len(best) == 1 and len(best[0].texts) == 0 and len(best[0].images) == 1
    assert all(len(ax.texts) == 0 for ax in _panels(captured["map_tip_residual_rms.png"]))
    assert "9 x 8 cells leave no room for names and values" in text


def test_ranking_uses_a_log_axis_across_decades_and_shows_every_run(selftest_out, captured):
    write_report(selftest_out)
    (ax,) = _panels(captured["ranking_tip_residual_rms.png"])
    rows = [r for r in _table(selftest_out) if r["status"] == "ok"]
    values = np.array([1e3 * r["tip_residual_rms"] for r in rows])
    assert ax.get_yscale() == ("log" if values.max() / values.min() > 20 else "linear")
    assert ax.get_ylabel().startswith("tip residual RMS (mm)")
    dots = np.concatenate([line.get_ydata() for line in ax.lines])
    np.testing.assert_allclose(
        np.sort(dots), np.sort(values)
    )  # one dot per ok run: the spread is shown


def test_a_spanning_ranking_is_logarithmic_and_a_narrow_one_is_not(tmp_path, captured):
    from flexctrl.study.report_figures import draw_ranking

    shown = display("tip_residual_rms")
    draw_ranking(
        tmp_path / "wide.png",
        {0.0: {"a": [0.008, 0.009], "b": [1.0, 1.2]}},
        ["a", "b"],
        "controller",
        "payload",
        shown,
    )
    draw_ranking(
        tmp_path / "narrow.png",
        {0.0: {"a": [0.8, 0.9], "b": [1.0, 1.2]}},
        ["a", "b"],
        "controller",
        "payload",
        shown,
    )
    assert _panels(captured["wide.png"])[0].get_yscale() == "log"
    assert _panels(captured["narrow.png"])[0].get_yscale() == "linear"


def _table(out: Path) -> list[dict]:
    from flexctrl.study.store import ResultStore

    return ResultStore(out).read_table().rows


CLOSED_LOOP_STUDY = """
name = "two_controllers"
executor = "closed_loop"
seed = 1
scene = "{root}/studies/scenes/move_joint1_30deg.toml"
model = "{root}/models/subedi3link.toml"
fidelity = "amm:1"
metrics = ["tip_residual_rms", "stable"]

[set]
"scene.duration" = 4.0

[grid]
controller = ["{root}/controllers/pd.toml", "{root}/controllers/lqr.toml"]

[trajectories]
decimation = 10

[report]
metric = "tip_residual_rms"
worst = 1
"""


def test_worst_case_overlays_every_controller_of_its_cell_like_compare(
    tmp_path, root, captured, capsys
):
    study = tmp_path / "two.toml"
    study.write_text(CLOSED_LOOP_STUDY.format(root=root.as_posix()))
    out = tmp_path / "out"
    assert cli.main(["study", str(study), "--out", str(out), "--workers", "0", "--quiet"]) == 0
    captured.clear()
    assert cli.main(["report", str(out)]) == 0  # the same figures from the folder alone
    worst = [name for name in captured if name.startswith("worst_")]
    assert len(worst) == 1
    fig = captured[worst[0]]
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert labels == [
        "tip error (mm)",
        "link tip deflection (mm)",
        "torque (N m)",
        "joint angle (deg)",
    ]
    tip, deflection, torque, joints = fig.axes
    assert len(tip.lines) == 2  # PD and LQR on the same axes
    assert len(deflection.lines) == 2 * 3  # every link of both runs
    limits = sorted(
        {
            abs(float(line.get_ydata()[0]))
            for line in torque.lines
            if len(set(line.get_ydata())) == 1
        }
    )
    assert limits == [50.0, 100.0, 200.0]  # the model file's torque limits, both signs drawn
    assert len(tip.patches) == 1 and tip.patches[0].get_x() == pytest.approx(
        2.5
    )  # window 2.5 s to the end
    assert len(joints.lines) == 2 * 3
    # the Python side: the same runs through fc.compare draw the same panels
    model = fc.load_model(
        SHIPPED / "models" / "subedi3link.toml",
        payload=2.0,
        fidelity="amm:1",
        gravity=[0.0, 0.0],
        overrides=[f"links[{i}].damping_ratio=0.005" for i in (1, 2, 3)],
    )
    op = fc.equilibrium(model, np.radians([30.0, 0.0, 0.0]))
    move = fc.Move(start=np.radians([0, 0, 0]), target=np.radians([30, 0, 0]), time=1.5)
    judge = fc.MetricSettings(settle_allowance=1.0)
    results = {
        name: fc.closed_loop(
            model,
            fc.design(model, op, fc.load_controller(SHIPPED / "controllers" / f"{name}.toml")),
            move,
            duration=4.0,
            metrics=judge,
        )
        for name in ("pd", "lqr")
    }
    python = fc.compare(results)
    assert [ax.get_ylabel() for ax in python.axes] == labels
    assert [len(ax.lines) for ax in python.axes] == [
        len(tip.lines),
        len(deflection.lines),
        len(torque.lines),
        len(joints.lines) + 3,
    ]  # + the reference of each joint
    # the report's stored residual RMS and the Python run agree (same scene, same controllers)
    rows = {r["controller"]: r["tip_residual_rms"] for r in _table(out)}
    for name, res in results.items():
        assert res.metrics["tip_residual_rms"] == pytest.approx(rows[name], rel=0.05)


def test_every_closed_loop_metric_has_a_unit_and_lengths_read_in_mm():
    from flexctrl.loop.metrics import JOINT_METRICS, METRICS, UNITS

    assert set(UNITS) == set(METRICS) | set(JOINT_METRICS)
    for name in METRICS:
        shown = display(name)
        if UNITS[name] == "m":
            assert shown.unit == "mm" and shown.scale == 1e3 and shown.label.endswith("(mm)"), name
        if UNITS[name] == "rad":
            assert shown.unit == "deg" and shown.scale == pytest.approx(180 / np.pi), name
    assert display("peak_torque_2").label == "peak torque 2 (N m)"
    assert display("wall_time_s").label == "wall time (s)"
