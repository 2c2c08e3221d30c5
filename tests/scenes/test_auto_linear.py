"""The estimate-first walk of ``fidelity = "auto"`` for closed loops (scenes/auto_linear.py).

Checked against the ladder walk and against nonlinear runs it did not make for its
estimate: the linear estimate of each rung (:mod:`flexctrl.scenes.auto_linear`) is
compared with the same formula on the nonlinear runs; the two walks' choices are
compared; the recorded ``estimated_error`` and ``reference_error`` are recomputed from
the nonlinear runs in the cache.  The small case is tests/scenes/test_auto_closed_loop.py's
(the quickstart's move cut to 2.8 s at (q2, q3) = (90, -90) deg, ladder to ``amm:2``,
reference ``amm:3``, the fixed full-state LQR).
"""

from __future__ import annotations

import numpy as np
import pytest

from flexctrl.errors import FlexctrlError
from flexctrl.fidelity.ladder import LINEAR_FACTOR, ToleranceUnreachable, tip_distance
from flexctrl.scenes import auto_closed_loop as auto_fidelity
from flexctrl.scenes.auto_linear import grid_maps, linear_closed_rung
from flexctrl.scenes.cache import SceneCache
from flexctrl.scenes.loop_setup import pin_design
from flexctrl.sim.rk4 import rk4_step
from flexctrl.spec.fidelity import parse_fidelity
from flexctrl.spec.scene import load_scene

SCENE = "studies/scenes/move_joint1_30deg.toml"
CONTROLLER = "tests/data/controllers/lqr_full_state.toml"
SHORT = ["duration=2.8", "initial.q=[0.0, 90.0, -90.0]", "fidelity='auto'", "tolerance=3e-3"]
TOL = 3e-3  # m
OPTIONS = {"top": 2, "reference": "amm:3"}
CACHE = SceneCache()


def _scene(*extra):
    return pin_design(load_scene(SCENE, [*SHORT, *extra]))


def _rung(m: int) -> str:
    return "rigid" if m == 0 else f"amm:{m}"


def _h(scene, m: int) -> float:
    return rk4_step(auto_fidelity.model_for(scene.plant, _rung(m), CACHE).omega_max, scene.plant.dt)


def test_rk4_grid_map_is_rk4_and_converges_to_the_exact_hold():
    rng = np.random.default_rng(3)
    A = rng.standard_normal((4, 4)) - 2 * np.eye(4)
    B = rng.standard_normal((4, 2))
    x, u, h = rng.standard_normal(4), rng.standard_normal(2), 1e-2
    # one RK4 step written out (classical stages, u held) against the map
    f = lambda z: A @ z + B @ u  # noqa: E731
    k1 = f(x)
    k2 = f(x + h / 2 * k1)
    k3 = f(x + h / 2 * k2)
    k4 = f(x + h * k3)  # noqa: E702
    P, G = grid_maps(A, B, h, h)
    np.testing.assert_allclose(
        P @ x + G @ u, x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), rtol=1e-13, atol=1e-14
    )
    # fourth order: 2 x the steps cut the error to the exact hold by about 16
    Pe, Ge = grid_maps(A, B, 0.1, None)
    errors = [np.abs(grid_maps(A, B, 0.1, 0.1 / n)[0] - Pe).max() for n in (5, 10)]
    assert 12 < errors[0] / errors[1] < 20


@pytest.mark.slow  # a few small compiled models and linearisations: ~15 s warm
def test_linear_estimate_is_within_the_stated_factor_of_the_nonlinear_distances():
    scene = _scene()
    lin = {
        m: linear_closed_rung(scene, _rung(m), _h(scene, m), controller=CONTROLLER, cache=CACHE)
        for m in (1, 2, 3)
    }
    nonlin = {
        m: auto_fidelity.simulate_closed_rung(scene, _rung(m), controller=CONTROLLER, cache=CACHE)
        for m in (1, 2, 3)
    }
    for m in (1, 2):
        for k in range(m + 1, 4):
            a, b = tip_distance(lin[k], lin[m]).max, tip_distance(nonlin[k], nonlin[m]).max
            assert b / LINEAR_FACTOR <= a <= b * LINEAR_FACTOR, (m, k, a, b)
    # and the linear runs are on the nonlinear runs' grid, the move itself being the same (same
    # controller)
    np.testing.assert_allclose(lin[3].time, nonlin[3].time, rtol=0, atol=1e-12)
    assert (
        np.abs(lin[3].tip - nonlin[3].tip).max()
        < 0.05 * np.abs(nonlin[3].tip - nonlin[3].tip[0]).max()
    )


@pytest.mark.slow
def test_estimate_walk_chooses_as_the_ladder_and_records_what_its_nonlinear_runs_measured():
    scene = _scene()
    ladder = auto_fidelity.choose_closed_loop_fidelity(
        scene, TOL, controller=CONTROLLER, cache=CACHE, walk="ladder", **OPTIONS
    )
    estimate = auto_fidelity.choose_closed_loop_fidelity(
        scene, TOL, controller=CONTROLLER, cache=CACHE, **OPTIONS
    )
    assert str(estimate.choice) == str(ladder.choice) and estimate.dt == ladder.dt
    assert estimate.evidence["walk"] == "estimate" and ladder.evidence["walk"] == "ladder"
    # the certificate: the nonlinear estimate of the choice, recomputed from the nonlinear runs,
    # meets the tolerance
    n = parse_fidelity(str(estimate.choice)).modes_per_link
    ref_n = parse_fidelity(OPTIONS["reference"]).count
    runs = {
        k: auto_fidelity.simulate_closed_rung(scene, _rung(k), controller=CONTROLLER, cache=CACHE)
        for k in range(n, min(n + 2, ref_n) + 1)
    }
    mine = 2.0 * max(tip_distance(runs[k], runs[n]).max for k in runs if k != n)
    assert estimate.estimated_error == pytest.approx(mine, rel=1e-12) and mine <= TOL
    assert estimate.estimated_error == pytest.approx(
        ladder.estimated_error, rel=1e-12
    )  # the same nonlinear runs
    # the reference is the reference model at its own step (a nonlinear run), and its error is
    # measured there
    ref = estimate.evidence["reference"]
    assert (
        ref["fidelity"] == OPTIONS["reference"]
        and ref["integrator"] == "rk4"
        and ref["dt_s"] == _h(scene, ref_n)
    )
    assert estimate.reference_error == pytest.approx(
        tip_distance(
            runs[ref_n]
            if ref_n in runs
            else auto_fidelity.simulate_closed_rung(
                scene, _rung(ref_n), controller=CONTROLLER, cache=CACHE
            ),
            runs[n],
        ).max,
        rel=1e-12,
    )
    # the ladder's reference (a smaller step) agrees with the estimate walk's to within the
    # tolerance's half
    assert abs(estimate.reference_error - ladder.reference_error) <= 0.5 * TOL
    assert estimate.evidence["linear_estimate"]["candidate"] is not None


# the quickstart's PD at full length: the ladder's walk alone is ~5 nonlinear runs
@pytest.mark.slow
def test_unreachability_is_predicted_where_the_ladder_walk_finds_it():
    scene = pin_design(
        load_scene(
            SCENE, ["payload=2.0", "initial.q=[0, 90, -90]", "fidelity='auto'", "tolerance=1e-3"]
        )
    )
    cache = SceneCache()
    with pytest.raises(ToleranceUnreachable) as ladder:
        auto_fidelity.choose_closed_loop_fidelity(
            scene, 1e-3, controller="controllers/pd.toml", cache=cache, walk="ladder"
        )
    before = cache.stats().get("closed_runs", {}).get("misses", 0)
    with pytest.raises(ToleranceUnreachable, match="predicted by the linear estimate") as predicted:
        auto_fidelity.choose_closed_loop_fidelity(
            scene, 1e-3, controller="controllers/pd.toml", cache=cache
        )
    assert (
        cache.stats().get("closed_runs", {}).get("misses", 0) == before
    )  # no nonlinear run was made
    evidence = predicted.value.evidence
    assert evidence["predicted"] and evidence["linear_estimate"]["candidate"] is None
    assert all(
        r.get("estimated_error_m", np.inf) > LINEAR_FACTOR * 1e-3
        for r in evidence["linear_estimate"]["rungs"]
        if "estimated_error_m" in r
    )
    assert ladder.value.evidence["best"]["estimated_error_m"] > 1e-3


# the small case with the MPC: its choice (linear and nonlinear runs) and two runs
@pytest.mark.slow
def test_the_run_at_the_choice_reuses_the_choices_own_run_and_equals_a_fresh_run():
    from flexctrl.scenes.run_closed_loop_scene import run_closed_loop_scene

    sets = [
        *SHORT,
        "controller_fidelity='amm:2'",
        "tolerance=1e-2",
    ]  # m: what the MPC's small case can meet
    scene = load_scene(SCENE, sets)
    cache = SceneCache()
    first = run_closed_loop_scene(
        scene, controller="controllers/mpc.toml", auto_options=OPTIONS, cache=cache, plots=False
    )
    assert "reused" in first.trajectory.meta  # the certifying run of the chosen rung, not run again
    again = run_closed_loop_scene(
        scene, controller="controllers/mpc.toml", auto_options=OPTIONS, cache=cache, plots=False
    )
    assert "reused" not in again.trajectory.meta  # taken once: the next run of the scene runs
    chosen = first.summary["fidelity_choice"]
    fixed = load_scene(
        SCENE,
        [
            *sets[:2],
            f"fidelity='{chosen['choice']}'",
            f"dt={chosen['dt_s']!r}",
            "controller_fidelity='amm:2'",
        ],
    )
    fresh = run_closed_loop_scene(
        fixed, controller="controllers/mpc.toml", cache=SceneCache(), plots=False
    )
    timing = {k for k in first.metrics if k.startswith("controller_time") or k.startswith("choice")}
    for run in (
        again,
        fresh,
    ):  # to the last digit: the same run, whatever ran before it in the process
        np.testing.assert_array_equal(run.trajectory.states, first.trajectory.states)
        np.testing.assert_array_equal(run.trajectory.inputs, first.trajectory.inputs)
        assert {k: v for k, v in run.metrics.items() if k not in timing} == {
            k: v for k, v in first.metrics.items() if k not in timing and k in run.metrics
        }


@pytest.mark.parametrize("name", ["pd", "shaped", "lqr", "lqg", "lqr_scheduled", "robust", "mpc"])
def test_has_sampled_law_says_before_a_step_what_sampled_law_gives_after_one(name):
    from flexctrl.scenes.auto_linear import loop_at

    ctrl = loop_at(
        _scene("controller_fidelity='amm:2'"), "amm:2", f"controllers/{name}.toml", (), CACHE
    ).controller
    ctrl.reset()
    said = ctrl.has_sampled_law()
    ctrl.step(0.0, np.zeros(ctrl.sensors.n_y))
    assert said == (ctrl.sampled_law() is not None)
    assert said == (
        name not in ("mpc", "lqr_scheduled")
    )  # the two that optimise or interpolate per sample


@pytest.mark.slow  # the small case with the MPC up to amm:3: 4 nonlinear runs of 2.8 s
def test_a_controller_stepped_in_python_walks_down_from_the_top_without_linear_runs():
    scene = _scene("controller_fidelity='amm:2'", "tolerance=1e-2")
    tol, mpc, cache = 1e-2, "controllers/mpc.toml", SceneCache()
    options = {
        "top": 3,
        "reference": "amm:4",
    }  # amm:1 fails, amm:2 and amm:3 meet 1e-2 m: the walk stops between
    choice = auto_fidelity.choose_closed_loop_fidelity(
        scene, tol, controller=mpc, cache=cache, **options
    )
    assert choice.evidence["linear_estimate_skipped"] and "linear_estimate" not in choice.evidence
    assert choice.evidence["walk_taken"] == "from_top"
    assert choice.evidence["bandwidth_rule"]["start"] == f"amm:{options['top']}"
    assert (
        choice.evidence["method"].startswith("closed loop")
        and "from the top rung down" in choice.evidence["method"]
    )
    # the rule, recomputed from the nonlinear runs: every rung from the choice to the top meets the
    # tolerance, the rung below the choice does not
    ref_n, top = parse_fidelity(options["reference"]).count, options["top"]
    low = 1  # the MPC measures strain: rigid cannot be built
    with pytest.raises(FlexctrlError, match="strain gauges"):
        auto_fidelity.simulate_closed_rung(scene, "rigid", controller=mpc, cache=cache)
    runs = {
        k: auto_fidelity.simulate_closed_rung(scene, _rung(k), controller=mpc, cache=cache)
        for k in range(low, ref_n + 1)
    }
    est = {
        m: 2.0
        * max(tip_distance(runs[k], runs[m]).max for k in range(m + 1, min(m + 2, ref_n) + 1))
        for m in range(low, top + 1)
    }
    n = parse_fidelity(str(choice.choice)).modes_per_link
    assert all(est[m] <= tol for m in range(n, top + 1)) and (n == low or est[n - 1] > tol), est
    assert low < n < top, est  # the case tests the stop between rungs
    assert choice.estimated_error == pytest.approx(est[n], rel=1e-12)
    # the reference's step check is the estimate walk's: its linear loop at its own step against the
    # exact hold, the only linear runs made
    assert cache.stats()["linear_runs"]["misses"] == 1
    exact = linear_closed_rung(scene, options["reference"], None, controller=mpc, cache=cache)
    at_h = linear_closed_rung(
        scene, options["reference"], runs[ref_n].dt, controller=mpc, cache=cache
    )
    assert (
        choice.evidence["reference"]["convergence"]["step_error_linear_m"]
        == tip_distance(exact, at_h).max
    )
    assert choice.evidence["bandwidth_rule"]["torques_from"].startswith(
        f"the closed loop with the plant at amm:{top}"
    )
    assert "linear_estimate" not in choice.evidence and choice.evidence["linear_estimate_skipped"]
    assert choice.evidence["walk_taken"] == "from_top"
    # a top rung that fails is a measured failure that says only the top was tried (the runs are in
    # the cache)
    with pytest.raises(ToleranceUnreachable, match="the top rung amm:3 does not meet") as failed:
        auto_fidelity.choose_closed_loop_fidelity(
            scene, 1e-6, controller=mpc, cache=cache, **options
        )
    assert failed.value.evidence["best"]["rung"] == "amm:3"
