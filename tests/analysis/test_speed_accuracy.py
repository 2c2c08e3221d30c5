"""Speed against accuracy (issue 7): tip error, reference convergence, RK4 order, Pareto front, the
study."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from support import DATA

from flexctrl.analysis.accuracy import compute_reference, pareto_front
from flexctrl.analysis.simulation_methods import Method, parse_method
from flexctrl.analysis.steppers import make_stepper, run_open_loop
from flexctrl.errors import SpecError
from flexctrl.sim.tip_error import tip_error
from flexctrl.study.executors import speed_accuracy_report as report
from flexctrl.study.executors import speed_vs_accuracy_executor as study

STUDY = DATA / "studies" / "speed_vs_accuracy.toml"


def _settings(
    scene: str, method: str, *extra: str, payload: float = 2.0, q=(0.0, 0.0, 0.0)
) -> dict:
    return {
        "scene": str(DATA / "studies" / "scenes" / scene),
        "model": str(DATA / "models" / "subedi3link.toml"),
        "controller": None,
        "payload": payload,
        "q0_deg": list(q),
        "fidelity": None,
        "overrides": sorted([f'scene.method="{method}"', *extra]),
        "digests": {},
        "seed": 1,
    }


# -- tip error ---------------------------------------------------------------------------


def test_tip_error_of_identical_runs_is_zero_and_of_a_shifted_path_is_the_shift():
    t = np.linspace(0.0, 1.0, 201)
    tip = np.column_stack([np.cos(3 * t), np.sin(2 * t)])
    same = tip_error(t, tip, t, tip)
    assert same.rms == 0.0 and same.max == 0.0
    shift = np.array([3e-3, -4e-3])  # a 5 mm rigid shift
    moved = tip_error(t, tip, t, tip + shift)
    assert moved.rms == pytest.approx(np.linalg.norm(shift), rel=1e-12)
    assert moved.max == pytest.approx(np.linalg.norm(shift), rel=1e-12)
    # a candidate on a coarser grid of the same (linear) path: interpolation is exact
    coarse = t[::4]
    line = np.column_stack([t, 2 * t])
    assert tip_error(t, line, coarse, line[::4]).max < 1e-14


# -- method spelling -----------------------------------------------------------------------


@pytest.mark.parametrize(
    "text",
    [
        "rigid/rk4@1ms",
        "amm:2/rk4@0.25ms",
        "amm:2+sched/rk4@1ms",
        "fem:4/rk4@stable",
        "fem:4/rk4@stable/2",
        "fem:4/newmark@1ms",
        "amm:2/cvodes@1e-06",
        "fem:2/idas@1e-05",
        "amm:2/scipy:DOP853@1e-06",
    ],
)
def test_method_spelling_round_trips(text):
    method = parse_method(text)
    assert parse_method(method.label) == method


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("amm:2/rk5@1ms", "did you mean 'rk4'"),
        ("fem:4+sched/rk4@1ms", "assumed modes only"),
        ("amm:2/rk4@1 parsec", "step"),
        ("amm:2/scipy:Euler@1e-6", "allowed: RK45"),
        ("amm:2/idas@3", "relative tolerance"),
        ("amm:2/newmark", "needs a step"),
        ("amm:2", "spelt"),
    ],
)
def test_bad_methods_are_refused_with_what_is_allowed(text, fragment):
    with pytest.raises(SpecError, match="allowed|did you mean|needs") as info:
        parse_method(text, source="study.toml", key="scene.method")
    assert fragment in str(info.value) and "study.toml" in str(info.value)


def test_bad_executor_settings_name_the_key():
    with pytest.raises(SpecError, match="scene.repeats"):
        study.plan_from_settings(_settings("bangbang.toml", "rigid/rk4@1ms", "scene.repeats=0"))
    with pytest.raises(SpecError, match="scene.method"):
        study.plan_from_settings(_settings("bangbang.toml", "rigid/rk4@1ms") | {"overrides": []})
    with pytest.raises(SpecError, match="finite-element reference"):
        study.plan_from_settings(
            _settings("bangbang.toml", "rigid/rk4@1ms", 'scene.reference="amm:2/rk4@1ms"')
        )


# -- the Pareto front ----------------------------------------------------------------------


def test_pareto_front_on_hand_made_points():
    cost = [1.0, 2.0, 3.0, 2.5, 0.5, 4.0, 2.0, math.nan]
    error = [1.0, 0.5, 0.1, 0.6, 2.0, 0.1, 0.5, 1e-9]
    # 3 is dominated by 1 (cheaper, more accurate); 5 ties 2 on error but costs more;
    # 6 equals 1 (neither dominates the other); the NaN point is never on the front
    assert pareto_front(cost, error).tolist() == [True, True, True, False, True, False, True, False]
    assert pareto_front([], []).tolist() == []
    with pytest.raises(ValueError):
        pareto_front([1.0, 2.0], [1.0])


def test_summary_marks_the_front_and_excludes_methods_with_failures():
    rows = []
    for scene in ("a", "b"):
        for method, cost, err, status in (
            ("rigid/rk4@1ms", 0.01, 1e-2, "ok"),
            ("amm:2/rk4@1ms", 0.02, 1e-3, "ok"),
            ("amm:3/rk4@1ms", 0.015, 1e-4, "failed" if scene == "b" else "ok"),
            ("fem:4/rk4@stable", 1.0, 1e-3, "ok"),
        ):
            rows.append(
                {
                    "scene": scene,
                    report.METHOD_COLUMN: method,
                    "status": status,
                    "error": "diverged" if status != "ok" else "",
                    "wall_per_sim_s": cost if status == "ok" else None,
                    "tip_error_rms": err if status == "ok" else None,
                    "tip_error_max": 2 * err if status == "ok" else None,
                    "n_states": 6.0,
                    "omega_max": 1.0,
                    "step_s": 1e-3,
                }
            )
    summary = {(s["scene"], s["method"]): s for s in report.summarise(rows)}
    assert (
        summary[("a", "amm:3/rk4@1ms")]["pareto"] and not summary[("a", "amm:2/rk4@1ms")]["pareto"]
    )
    assert (
        not summary[("b", "amm:3/rk4@1ms")]["pareto"] and summary[("b", "amm:2/rk4@1ms")]["pareto"]
    )
    assert not summary[(report.ALL, "fem:4/rk4@stable")]["pareto"]
    assert summary[(report.ALL, "amm:3/rk4@1ms")]["runs_failed"] == 1


# -- numerics: RK4 order and the reference's convergence ------------------------------------


def test_rk4_error_falls_as_h4_against_a_tight_implicit_solution():
    """amm:1, bang-bang at 0 kg for 0.05 s: RK4 at h, h/2, h/4 against CVODES at rtol 1e-11."""
    plan = study.plan_from_settings(
        _settings("bangbang.toml", "amm:1/rk4@1ms", "scene.horizon=0.05", payload=0.0)
    )
    tight, _ = study.simulate_method(plan, parse_method("amm:1/cvodes@1e-11"))
    errors = []
    for step in ("1ms", "0.5ms", "0.25ms"):
        run, _ = study.simulate_method(plan, parse_method(f"amm:1/rk4@{step}"))
        errors.append(np.max(np.abs(run.states - tight.states)))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all((orders > 3.5) & (orders < 4.5)), (errors, orders)


def test_reference_converges_with_mesh_and_step(monkeypatch):
    """Reduced check (0.1 s of the bang-bang scene): halving the step changes the reference far less
    than the
    mesh does, and the finer mesh pair (fem:4 vs fem:2 -> fem:3 vs fem:4) differs less."""
    monkeypatch.setenv(
        "FLEXCTRL_NO_COMPILE", "1"
    )  # the virtual machine: no compile time for a short run
    plan = study.plan_from_settings(
        _settings("bangbang.toml", "rigid/rk4@1ms", "scene.horizon=0.1", payload=0.5)
    )
    ref = compute_reference(
        lambda m: study.simulate_method(plan, m)[0],
        parse_method("fem:4/rk4@stable"),
        ["fem:2", "fem:3"],
    )
    step, coarse, middle = ref.checks["step/2"], ref.checks["fem:2"], ref.checks["fem:3"]
    assert middle["max"] < coarse["max"]
    assert step["max"] < 0.1 * middle["max"]  # time error an order below the mesh error
    assert ref.tip.shape == (ref.time.size, 2) and np.all(np.isfinite(ref.tip))


def test_open_loop_driver_matches_the_package_integrator():
    """The stepper layer reproduces flexctrl.sim's RK4 at the same step (same torque samples)."""
    from flexctrl.scenes import run_scene
    from flexctrl.spec.scene import load_scene

    scene = load_scene(
        DATA / "studies" / "scenes" / "bangbang.toml", ["duration=0.3", "fidelity='amm:1'"]
    )
    direct = run_scene(scene).trajectory
    plan = study.plan_from_settings(
        _settings("bangbang.toml", "amm:1/rk4@1ms", "scene.horizon=0.3")
    )
    run, _ = study.simulate_method(plan, plan.method)
    assert np.max(np.abs(run.tip - direct.tip)) < 1e-10


def test_divergence_is_an_error_not_nan():
    from flexctrl.dynamics.build import build_model
    from flexctrl.errors import SimulationError
    from flexctrl.scenes.arm_setup import scene_arm

    plan = study.plan_from_settings(
        _settings("bangbang.toml", "fem:2/rk4@1ms", "scene.horizon=0.3")
    )
    scene = study._scene(study._plan_scene(plan))
    arm = scene_arm(scene)
    model = build_model(arm, "fem:2", reference_q=scene.q0)
    stepper = make_stepper(model, Method("fem:2", step=1e-3), compile=False)
    torque = scene.input.samples(300, 1e-3, 3)
    with pytest.raises(SimulationError, match="diverged"):
        run_open_loop(stepper, np.zeros(model.n_x), torque)


# -- the study ---------------------------------------------------------------------------------


def test_reduced_study_writes_pareto_csv_and_the_figure(tmp_path, monkeypatch):
    from flexctrl.study.runner import run_study
    from flexctrl.study.study_file import load_study

    monkeypatch.setenv("FLEXCTRL_CACHE", str(tmp_path / "cache"))
    overrides = [
        'grid={scene = ["scenes/bangbang.toml"], payload = [0.0], configuration = [[0, 0, 0]], '
        '"scene.method" = ["rigid/rk4@1ms", "amm:1/rk4@1ms", "amm:1/cvodes@1e-6"]}',
        'set={"scene.horizon" = 0.1, "scene.reference" = "fem:3/rk4@stable", '
        '"scene.reference_meshes" = ["fem:2"], '
        '"scene.repeats" = 2, "controller.sensors.outputs" = ["joints", "deflection"]}',
        'metrics=["tip_error_rms", "tip_error_max", "wall_per_sim_s", "ref_step2_max", '
        '"ref_fem2_max"]',
    ]
    spec = load_study(STUDY, overrides)
    assert len(spec.runs) == 3
    out = tmp_path / "out"
    run_study(spec, out, workers=0, progress="none")
    rows = list(csv.DictReader(open(out / "results.csv")))
    assert [r["status"] for r in rows] == ["ok"] * 3
    errors = {r["scene.method"]: float(r["tip_error_rms"]) for r in rows}
    # one mode is closer to the FE reference than none
    assert errors["amm:1/rk4@1ms"] < errors["rigid/rk4@1ms"]
    pareto = list(csv.DictReader(open(out / "pareto.csv")))
    assert {p["method"] for p in pareto} == set(errors)
    assert any(p["pareto"] == "True" for p in pareto)
    assert (out / "figures" / "pareto.png").stat().st_size > 10_000
    report = (out / "report.md").read_text()
    assert "## Speed against accuracy" in report and "The reference and its convergence" in report
    # the reference was cached on disk and is reused
    assert len(list((tmp_path / "cache" / "accuracy").glob("reference_*.npz"))) == 1
