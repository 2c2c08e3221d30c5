"""The closed loop chained in CasADi against the same controller stepped once per sample.

A controller with a sampled law runs its samples after the first chained in CasADi; the
same controller with its law hidden is stepped from Python, the path every controller
without a law takes.  Same plant step, same controller arithmetic, the same noise draws:
the trajectories agree to round-off (the controllers' matrix products sum in another
order), the divergence verdicts exactly.
"""

import contextlib
import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from flexctrl.bench.loop_overhead import metric_differences
from flexctrl.loop import compiled
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


@contextlib.contextmanager
def stepped_in_python(controller):
    """The controller without its sampled law: the loop steps it once per sample from Python."""
    controller.sampled_law = lambda: None
    try:
        yield controller
    finally:
        del controller.sampled_law


def run(scene, controller, cache, overrides=()):
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
    )
    ctrl = setup.controller
    return traj, samples, ctrl.stats.summary(), np.array(ctrl.u_previous)


def both(scene, controller, cache, overrides=()):
    """The run stepped in Python and chained in CasADi, on one cached design."""
    design = build_loop(scene, controller, overrides, cache).controller
    with stepped_in_python(design):
        python = run(scene, controller, cache, overrides)
    return {"python": python, "compiled": run(scene, controller, cache, overrides)}


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
    with stepped_in_python(build_loop(scene, scene.controller, (), cache).controller):
        a = run_closed_loop_scene(scene, cache=cache, on_divergence="record")
    b = run_closed_loop_scene(scene, cache=cache, on_divergence="record")
    assert a.trajectory.meta["loop"] == "python" and b.trajectory.meta["loop"] == "compiled"
    a, b = a.metrics, b.metrics
    differences = metric_differences(a, b)
    assert max(differences.values()) <= TOL, differences
    assert a["settled"] == b["settled"] and a["stable"] == b["stable"]


def test_divergence_is_the_same(cache):
    """An unfiltered, fast sampled PD is unstable on the light hubs: both paths stop alike."""
    overrides = ("torque_filter=0", "bandwidth=8.0", "saturate=false")
    runs = both(short_scene(), "controllers/pd.toml", cache, overrides)
    (tp, sp, stp, _), (tc, sc, stc, _) = runs["python"], runs["compiled"]
    assert tp.meta["divergence"] is not None
    assert tp.meta["divergence"] == tc.meta["divergence"]
    assert tp.states.shape == tc.states.shape and sp.size == sc.size == stp["steps"] == stc["steps"]
    finite = np.all(np.isfinite(tp.states), axis=1)
    assert_close(tp.states[finite], tc.states[finite], 1e-6)


def test_a_controller_without_a_sampled_law_is_stepped_in_python(cache):
    scene = short_scene(duration=0.5)
    setup = build_loop(scene, "controllers/mpc.toml", (), cache)
    assert setup.controller.sampled_law() is None
    traj, samples = simulate_closed_loop(
        setup.plant, setup.controller, setup.x0, 0.5, scene.plant.dt, sensors=setup.sensors
    )
    assert traj.meta["loop"] == "python"
    assert setup.controller.stats.summary()["steps"] == samples.size > 1


def test_design_is_kept_and_reset(cache):
    """A second run on the cached design gives the first run's metrics."""
    scene = dataclasses.replace(short_scene(noise=True), controller="controllers/pd.toml")
    fresh = run_closed_loop_scene(scene, cache=SceneCache(), on_divergence="record").metrics
    run_closed_loop_scene(scene, cache=cache, on_divergence="record")
    again = run_closed_loop_scene(scene, cache=cache, on_divergence="record").metrics
    assert max(metric_differences(fresh, again).values()) == 0.0


@pytest.mark.parametrize("controller", ["controllers/lqg.toml", "controllers/pd.toml"])
def test_chained_in_chunks_equals_one_chain_to_the_last_digit(controller, cache, monkeypatch):
    # the loop is chained in calls of at most CHUNK samples, fewer when a call would hold more
    # than CHUNK_STEPS plant steps; 7 leaves a remainder, so both the full and the last, shorter
    # chunk run; CHUNK_STEPS = 1 makes every call one sample
    scene = short_scene(noise=True)
    runs = {}
    for name, chunk, states in (("whole", 10**6, 10**12), ("7", 7, 10**12), ("1", 128, 1)):
        monkeypatch.setattr(compiled, "CHUNK", chunk)
        monkeypatch.setattr(compiled, "CHUNK_STEPS", states)
        runs[name] = run(scene, controller, cache)
    a, sa, stats_a, ua = runs["whole"]
    assert a.states.shape[0] > 7 * 15
    for b, sb, stats_b, ub in (runs["7"], runs["1"]):
        np.testing.assert_array_equal(sa, sb)
        np.testing.assert_array_equal(a.states, b.states)
        np.testing.assert_array_equal(a.inputs, b.inputs)
        np.testing.assert_array_equal(ua, ub)
        assert kept(stats_a) == kept(stats_b) and kept(stats_a)["steps"] == len(sa)


def kept(stats):
    """The statistics that are not wall times."""
    return {k: v for k, v in stats.items() if not k.endswith("_ms") and k != "median_iterations"}


def test_a_call_holds_at_most_chunk_steps_plant_steps():
    def size(substeps):
        return compiled.chunk_size(SimpleNamespace(substeps=substeps))

    assert size(17) == compiled.CHUNK  # the scenes' LQR on amm:2: 128 samples a call
    assert size(260) == compiled.CHUNK_STEPS // 260  # amm:5 at its stable step under a 10 ms LQR
    assert size(4029) == 1  # finite elements: thousands of steps per sample, one sample a call


def test_the_deflection_monitor_stops_both_loops_alike(cache):
    # a limit of 0.2 % of each link's length (2-3 mm): the move's own deflections (about 11 mm on
    # link 1) trip it, so the Python loop's per-sample monitor call (bound to arrays for the run)
    # and the compiled loop's batched flags must stop at the same sample for the same reason
    scene = dataclasses.replace(short_scene(), divergence_deflection=0.002)
    runs = both(scene, "controllers/lqr.toml", cache)
    (tp, sp, _, _), (tc, sc, _, _) = runs["python"], runs["compiled"]
    assert tp.meta["divergence"] is not None and "tip deflection" in tp.meta["divergence"]["reason"]
    assert tp.meta["divergence"] == tc.meta["divergence"] and sp.size == sc.size
