"""What a study worker reuses between runs is keyed on everything it depends on.

Reused: models, designs, reference tables.

A worker's :class:`~flexctrl.scenes.cache.SceneCache` keeps models, designed controllers
and reference trajectories under plain-data keys.  Each run below goes through ONE
cache after runs that differ from it in one input (configuration, payload, move,
deflection, controller settings, sample time); its metrics must equal those of the same
run on a fresh cache, to the last digit.  A key that forgot an input would hand the run
another run's model, design or table, and the metrics would differ.  And the compiled
reference tables against the virtual machine's
(:func:`flexctrl.control.reference_trajectory.path_functions`).
"""

import dataclasses

import numpy as np
import pytest

from flexctrl.bench.loop_overhead import TIMING_METRICS
from flexctrl.control.reference_trajectory import ReferenceTrajectory, path_functions
from flexctrl.scenes.arm_setup import scene_arm
from flexctrl.scenes.cache import SceneCache
from flexctrl.scenes.run_closed_loop_scene import run_closed_loop_scene
from flexctrl.spec.scene import load_scene

SCENE = "studies/scenes/move_joint1_30deg.toml"

#: One scene per input the reuse must not ignore; each differs from the first in that input alone.
VARIANTS = {
    "nominal": [],
    "configuration": ["initial.q=[0.0, 0.0, -90.0]"],
    "payload": ["payload=1.0"],
    "move": ["target.move=[20.0, 0.0, 0.0]"],
    "move_time": ["target.move_time=1.2"],
    "deflection": ['target.deflection="static"'],
}


def scene(overrides, controller):
    base = load_scene(SCENE, overrides)
    return dataclasses.replace(
        base, plant=dataclasses.replace(base.plant, duration=2.5), controller=controller
    )


def metrics(result):
    return {k: v for k, v in result.metrics.items() if k not in TIMING_METRICS}


@pytest.mark.parametrize(
    "controller, overrides",
    [
        ("controllers/lqr.toml", ()),
        ("controllers/pd.toml", ()),
        ("controllers/mpc.toml", ()),
    ],
)
def test_runs_through_one_cache_equal_runs_on_fresh_caches(controller, overrides):
    shared = SceneCache()
    seen = {}
    for name, scene_overrides in VARIANTS.items():
        run = scene(scene_overrides, controller)
        reused = run_closed_loop_scene(
            run, cache=shared, on_divergence="record", overrides=overrides
        )
        fresh = run_closed_loop_scene(
            run, cache=SceneCache(), on_divergence="record", overrides=overrides
        )
        assert metrics(reused) == metrics(fresh), name
        seen[name] = fresh.metrics["tip_residual_rms"]
    # the variants are different runs (a test comparing a run with itself would pass whatever the
    # keys), except the deflection for PD: it reads the reference's rigid part only (elastic=False),
    # the same for both
    same = {"deflection"} if "pd" in controller else set()
    assert all(
        seen[name] != seen["nominal"] for name in VARIANTS if name != "nominal" and name not in same
    )
    stats = shared.stats()
    assert (
        stats["designs"]["misses"] == len(VARIANTS) and stats["models"]["misses"] == 3
    )  # nominal, config, payload


def test_controller_settings_and_sample_time_are_part_of_the_keys():
    """Two controllers on one model share its reference (a table per sample time), not a design."""
    shared = SceneCache()
    run = scene([], "controllers/lqr.toml")
    variants = [(), ("sample_time=0.0075",), ("weights.modal=0.03",)]
    for overrides in variants:
        reused = run_closed_loop_scene(
            run, cache=shared, on_divergence="record", overrides=overrides
        )
        fresh = run_closed_loop_scene(
            run, cache=SceneCache(), on_divergence="record", overrides=overrides
        )
        assert metrics(reused) == metrics(fresh), overrides
    stats = shared.stats()
    assert stats["designs"]["misses"] == len(variants)
    assert stats["references"] == {"entries": 1, "hits": len(variants) - 1, "misses": 1}
    reference = next(iter(shared._stores["references"].values()))
    assert sorted(Ts for Ts, _ in reference._tables) == [0.0075, 0.0085]


def test_a_reference_is_shared_only_on_the_same_model_path_and_deflection():
    cache = SceneCache()
    base = load_scene(SCENE)
    arm = scene_arm(base.plant)
    path = base.joint_reference()
    a = cache.reference(arm, "amm:2", "frozen", (0.0, 0.0, 0.0), path, "quasi_static")
    assert cache.reference(arm, "amm:2", "frozen", (0, 0, 0), path, "quasi_static") is a
    others = [
        cache.reference(arm, "amm:2", "frozen", (0.0, 0.0, -1.0), path, "quasi_static"),
        cache.reference(
            arm.with_payload(1.0), "amm:2", "frozen", (0.0, 0.0, 0.0), path, "quasi_static"
        ),
        cache.reference(arm, "amm:1", "frozen", (0.0, 0.0, 0.0), path, "quasi_static"),
        cache.reference(
            arm,
            "amm:2",
            "frozen",
            (0.0, 0.0, 0.0),
            dataclasses.replace(path, move_time=1.0),
            "quasi_static",
        ),
        cache.reference(arm, "amm:2", "frozen", (0.0, 0.0, 0.0), path, "static"),
        cache.reference(
            arm, "amm:2", "frozen", (0.0, 0.0, 0.0), path, "quasi_static", compile=None
        ),
    ]
    assert all(o is not a for o in others)
    x = a.window(0.0, 0.01, 120)[0]
    for other in others[:-1]:  # the compiled one has the same table to round-off
        assert not np.array_equal(other.window(0.0, 0.01, 120)[0], x)


def relative(a, b):
    scale = np.maximum(np.abs(a), np.abs(b))
    return float(
        np.max(
            np.where(
                scale > 1e-12, np.abs(a - b) / np.where(scale > 1e-12, scale, 1.0), np.abs(a - b)
            ),
            initial=0.0,
        )
    )


@pytest.mark.parametrize("q0", [(0.0, 0.0, 0.0), (0.0, 1.5707963267948966, -1.5707963267948966)])
def test_compiled_reference_tables_match_the_virtual_machine(q0):
    """The compiled Newton's tables within 1e-9 of the VM's, at two configurations of one shape.

    The second configuration loads the first's library (one per model shape): its
    constants, bound in the wrapper, must be its own (the tables differ between the
    configurations by far more than the tolerance).
    """
    base = load_scene(
        SCENE, ["gravity=[0.0, -9.81]"]
    )  # in a vertical plane: a static deflection and torque
    cache = SceneCache()
    model = cache.model(scene_arm(base.plant), "amm:2", "frozen", q0)
    assert path_functions(model, None)["all"].name() == "reference_all"
    assert path_functions(model, None) is not path_functions(model, False)
    for Ts, elastic in ((0.001, False), (0.0085, True)):
        vm = ReferenceTrajectory(model, base.joint_reference(), "quasi_static", compile=False)
        compiled = ReferenceTrajectory(model, base.joint_reference(), "quasi_static", compile=None)
        for a, b in zip(
            vm.window(0.0, Ts, 400, elastic=elastic), compiled.window(0.0, Ts, 400, elastic=elastic)
        ):
            assert relative(a, b) <= 1e-9
            assert np.max(np.abs(a)) > 0
    straight = cache.model(scene_arm(base.plant), "amm:2", "frozen", (0.0, 0.0, 0.0))
    if straight is not model:
        other = ReferenceTrajectory(straight, base.joint_reference(), "quasi_static", compile=None)
        assert (
            relative(other.window(0.0, 0.0085, 400)[0], compiled.window(0.0, 0.0085, 400)[0]) > 1e-6
        )
