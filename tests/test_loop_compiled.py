"""The compiled closed loop (one CasADi call for all samples after the first) against the Python
loop.

Same plant step, same controller arithmetic, the same noise draws: the trajectories
agree to round-off (the controllers' matrix products and the compiled output map sum
in another order), the divergence verdicts exactly.
"""

import dataclasses

import numpy as np
import pytest

from flexctrl.bench.loop_overhead import metric_differences
from flexctrl.errors import SpecError
from flexctrl.loop.sampled import simulate_closed_loop
from flexctrl.scenes.cache import SceneCache
from flexctrl.scenes.loop_setup import build_loop
from flexctrl.scenes.run_closed_loop_scene import run_closed_loop_scene
from flexctrl.spec.scene import load_scene

SCENE = "studies/scenes/move_joint1_30deg.toml"
TOL = 1e-9


@pytest.fixture(scope="module")
def cache():
    return SceneCache()


def short_scene(duration=3.6, noise=False):
    scene = load_scene(SCENE)
    return dataclasses.replace(
        scene, plant=dataclasses.replace(scene.plant, duration=duration), noise=noise
    )


def both(scene, controller, cache, overrides=(), loops=("python", "compiled")):
    out = {}
    for loop in loops:
        setup = build_loop(scene, controller, overrides, cache)
        rng = np.random.default_rng(scene.seed) if scene.noise else None
        traj, samples = simulate_closed_loop(
            setup.plant,
            setup.controller,
            setup.x0,
            scene.plant.duration,
            scene.plant.dt,
            sensors=setup.sensors,
            rng=rng,
            monitor=setup.monitor,
            stop_on_divergence=True,
            loop=loop,
        )
        ctrl = setup.controller
        out[loop] = (traj, samples, ctrl.stats.summary(), np.array(ctrl.u_previous))
    return out


def assert_close(a, b, tol=TOL):
    """Arrays equal to ``tol`` relative to each column's magnitude."""
    assert a.shape == b.shape
    scale = np.maximum(np.max(np.abs(a), axis=0), 1e-300)
    assert np.max(np.abs(a - b) / scale) <= tol


@pytest.mark.parametrize(
    "controller, noise, overrides",
    [
        ("controllers/lqr.toml", False, ()),  # Kalman filter on encoders and strain gauges
        ("controllers/lqg.toml", True, ()),  # with a tip accelerometer (feed-through) and noise
        ("controllers/lqr_ideal.toml", False, ()),  # full state
        ("controllers/pd.toml", True, ()),
        ("controllers/pd.toml", False, ("gravity=measured",)),
        ("controllers/shaped.toml", False, ()),
    ],
)
def test_compiled_loop_matches_python(controller, noise, overrides, cache):
    runs = both(short_scene(noise=noise), controller, cache, overrides)
    (tp, sp, stp, up), (tc, sc, stc, uc) = runs["python"], runs["compiled"]
    assert tp.meta["loop"] == "python" and tc.meta["loop"] == "compiled"
    np.testing.assert_array_equal(sp, sc)
    np.testing.assert_array_equal(tp.time, tc.time)
    for name in ("states", "inputs", "tip", "deflections"):
        assert_close(getattr(tp, name), getattr(tc, name))
    for name in tp.energies:
        assert_close(tp.energies[name][:, None], tc.energies[name][:, None])
    assert (
        stp["steps"] == stc["steps"]
        and stp["status"] == stc["status"]
        and stp["saturated"] == stc["saturated"]
    )
    np.testing.assert_allclose(up, uc, rtol=TOL, atol=TOL * np.max(np.abs(tp.inputs)))


def test_scene_metrics_match(cache):
    scene = dataclasses.replace(short_scene(noise=True), controller="controllers/lqg.toml")
    a, b = (
        run_closed_loop_scene(scene, cache=cache, on_divergence="record", loop=loop).metrics
        for loop in ("python", "compiled")
    )
    differences = metric_differences(a, b)
    assert max(differences.values()) <= TOL, differences
    assert a["settled"] == b["settled"] and a["stable"] == b["stable"]


def test_divergence_is_the_same(cache):
    """An unfiltered, fast sampled PD is unstable on the light hubs (control/pd.py): both paths stop alike."""
    overrides = ("torque_filter=0", "bandwidth=8.0", "saturate=false")
    runs = both(short_scene(), "controllers/pd.toml", cache, overrides)
    (tp, sp, stp, _), (tc, sc, stc, _) = runs["python"], runs["compiled"]
    assert tp.meta["divergence"] is not None
    assert tp.meta["divergence"] == tc.meta["divergence"]
    assert tp.states.shape == tc.states.shape and sp.size == sc.size == stp["steps"] == stc["steps"]
    finite = np.all(np.isfinite(tp.states), axis=1)
    assert_close(tp.states[finite], tc.states[finite], 1e-6)


def test_loop_option_is_checked(cache):
    scene = short_scene()
    setup = build_loop(scene, "controllers/mpc.toml", (), cache)
    with pytest.raises(SpecError, match="no sampled law"):
        simulate_closed_loop(
            setup.plant,
            setup.controller,
            setup.x0,
            0.5,
            scene.plant.dt,
            sensors=setup.sensors,
            loop="compiled",
        )
    with pytest.raises(SpecError, match="'auto', 'compiled', 'python'"):
        simulate_closed_loop(
            setup.plant, setup.controller, setup.x0, 0.5, scene.plant.dt, loop="fast"
        )


def test_design_is_kept_and_reset(cache):
    """A second run on the cached design gives the first run's metrics."""
    scene = dataclasses.replace(short_scene(noise=True), controller="controllers/pd.toml")
    fresh = run_closed_loop_scene(scene, cache=SceneCache(), on_divergence="record").metrics
    run_closed_loop_scene(scene, cache=cache, on_divergence="record")
    again = run_closed_loop_scene(scene, cache=cache, on_divergence="record").metrics
    assert max(metric_differences(fresh, again).values()) == 0.0


@pytest.mark.parametrize("controller", ["controllers/lqg.toml", "controllers/pd.toml"])
def test_chained_in_chunks_equals_one_chain_to_the_last_digit(controller, cache, monkeypatch):
    # the loop is chained in calls of CHUNK samples (building one mapaccum over the whole run costs
    # time
    # in proportion to its length); 7 leaves a remainder, so both the full and the last, shorter
    # chunk run
    import flexctrl.loop.compiled as compiled

    scene = short_scene(noise=True)
    runs = {}
    for chunk in (None, 7):
        monkeypatch.setattr(compiled.run_compiled, "__defaults__", (chunk,))
        runs[chunk] = both(scene, controller, cache, loops=("compiled",))["compiled"]
    (a, sa, stats_a, ua), (b, sb, stats_b, ub) = runs[None], runs[7]
    np.testing.assert_array_equal(sa, sb)
    assert a.states.shape[0] > 7 * 15
    np.testing.assert_array_equal(a.states, b.states)
    np.testing.assert_array_equal(a.inputs, b.inputs)
    np.testing.assert_array_equal(ua, ub)
    kept = lambda stats: {
        k: v for k, v in stats.items() if not k.endswith("_ms") and k != "median_iterations"
    }  # noqa: E731
    assert kept(stats_a) == kept(stats_b) and kept(stats_a)["steps"] == len(sa)


def test_the_deflection_monitor_stops_both_loops_alike(cache):
    # a limit of 0.2 % of each link's length (2-3 mm): the move's own deflections (about 11 mm on
    # link 1) trip it,
    # so the Python loop's per-sample monitor call (bound to arrays for the run) and the compiled
    # loop's
    # batched flags must stop at the same sample for the same reason
    scene = dataclasses.replace(short_scene(), divergence_deflection=0.002)
    runs = both(scene, "controllers/lqr.toml", cache)
    (tp, sp, _, _), (tc, sc, _, _) = runs["python"], runs["compiled"]
    assert tp.meta["divergence"] is not None and "tip deflection" in tp.meta["divergence"]["reason"]
    assert tp.meta["divergence"] == tc.meta["divergence"] and sp.size == sc.size
