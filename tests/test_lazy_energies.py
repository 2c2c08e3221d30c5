"""A closed loop's energies are evaluated when first read, with the same values as the eager path.

The tip and deflections come from a map without the energies (its own compiled code), so
they agree with the full output map to round-off, not to the bit; the energies, when read,
come from the full map itself, so they are the eager path's to the bit.
"""

import copy
import dataclasses
import pickle

import numpy as np
import pytest

from flexctrl.errors import SpecError
from flexctrl.loop.plant_step import output_map
from flexctrl.loop.sampled import (
    integrate_closed_loop,
    mapped,
    tip_positions,
    trajectory_from_states,
)
from flexctrl.scenes.cache import SceneCache
from flexctrl.scenes.loop_setup import build_loop
from flexctrl.scenes.run_closed_loop_scene import run_closed_loop_scene
from flexctrl.sim.bound import evaluate
from flexctrl.sim.trajectory import ENERGY_NAMES, LazyEnergies
from flexctrl.spec.scene import load_scene

SCENE = "studies/scenes/move_joint1_30deg.toml"


@pytest.fixture(scope="module")
def run():
    scene = load_scene(SCENE)
    scene = dataclasses.replace(
        scene,
        plant=dataclasses.replace(scene.plant, duration=3.0),
        noise=False,
        controller="controllers/lqr.toml",
    )
    cache = SceneCache()
    setup = build_loop(scene, scene.controller, (), cache)
    t, X, U, meta, _ = integrate_closed_loop(
        setup.plant,
        setup.controller,
        setup.x0,
        scene.plant.duration,
        scene.plant.dt,
        monitor=setup.monitor,
        stop_on_divergence=True,
    )
    return scene, cache, setup.plant, t, X, U, meta


@pytest.mark.parametrize("compiled", [True, False])
def test_lazy_energies_are_the_eager_ones(run, compiled):
    _, _, plant, t, X, U, meta = run
    eager = trajectory_from_states(plant, t, X, U, meta, compiled=compiled, energies="eager")
    lazy = trajectory_from_states(plant, t, X, U, meta, compiled=compiled)
    assert isinstance(eager.energies, dict)
    assert isinstance(lazy.energies, LazyEnergies) and not lazy.energies.evaluated
    assert list(lazy.energies) == list(ENERGY_NAMES) and len(lazy.energies) == 4
    assert lazy.energies.evaluated is False  # iterating over the names computes nothing
    for name in ENERGY_NAMES:
        np.testing.assert_array_equal(lazy.energies[name], eager.energies[name])
    assert lazy.energies.evaluated
    assert np.ptp(eager.energies["E_kin"]) > 0  # a moving arm: the comparison compares something
    np.testing.assert_array_equal(
        lazy.energies["E_total"],
        eager.energies["E_kin"] + eager.energies["E_el"] + eager.energies["E_grav"],
    )
    scale = np.max(np.abs(eager.tip))
    assert np.max(np.abs(lazy.tip - eager.tip)) <= 1e-14 * scale
    assert np.max(np.abs(lazy.deflections - eager.deflections)) <= 1e-14 * max(
        np.max(np.abs(eager.deflections)), 1e-3
    )
    with pytest.raises(KeyError):
        lazy.energies["E_wrong"]


def test_tip_rows_come_from_the_map_without_energies(run):
    _, _, plant, t, X, U, meta = run
    full = evaluate(output_map(plant, t.size), X)[0]
    kinematic = evaluate(output_map(plant, t.size, energies=False), X)[0]
    assert kinematic.shape == (t.size, full.shape[1] - 3)
    np.testing.assert_allclose(
        kinematic, full[:, 3:], rtol=0, atol=1e-14 * np.max(np.abs(full[:, 3:5]))
    )
    lazy = trajectory_from_states(plant, t, X, U, meta, compiled=True)
    np.testing.assert_array_equal(lazy.tip, kinematic[:, :2])
    np.testing.assert_array_equal(lazy.deflections, kinematic[:, 2:])


def test_lazy_energies_mapping():
    calls = []
    kin, el, grav = np.array([1.0, 2.0]), np.array([0.5, 0.25]), np.array([-3.0, 4.0])

    def compute():
        calls.append(1)
        return kin, el, grav

    energies = LazyEnergies(compute)
    assert not calls and "E_kin" in energies and not calls
    np.testing.assert_array_equal(energies["E_total"], [-1.5, 6.25])
    np.testing.assert_array_equal(energies["E_grav"], grav)
    assert len(calls) == 1  # computed once


def test_tip_positions_are_the_trajectorys_tip(run):
    """The fidelity chooser's tip paths: the compiled map's, within round-off of the VM's mapped calls."""
    _, _, plant, t, X, U, meta = run
    tip = tip_positions(plant, X[::7])
    np.testing.assert_array_equal(
        tip, trajectory_from_states(plant, t, X, U, meta, compiled=True).tip[::7]
    )
    vm = np.array(
        mapped(plant, "tip", tip.shape[0], X[::7, : plant.n_q].T, X[::7, plant.n_q :].T)[0]
    ).T
    assert np.max(np.abs(tip - vm)) <= 1e-14 * np.max(np.abs(vm))


def test_copies_and_pickles_are_plain_dicts(run):
    _, _, plant, t, X, U, meta = run
    lazy = trajectory_from_states(plant, t, X, U, meta, compiled=True)
    for other in (copy.deepcopy(lazy.energies), pickle.loads(pickle.dumps(lazy.energies))):
        assert type(other) is dict and list(other) == list(ENERGY_NAMES)
        for name in ENERGY_NAMES:
            np.testing.assert_array_equal(other[name], lazy.energies[name])


def test_the_scene_metrics_do_not_read_the_energies(run):
    scene, cache, *_ = run
    lazy = run_closed_loop_scene(scene, cache=cache, on_divergence="record")
    assert not lazy.trajectory.energies.evaluated
    eager = run_closed_loop_scene(scene, cache=cache, on_divergence="record", energies="eager")
    timing = ("controller_time_median", "controller_time_p95", "controller_time_max")
    for key, value in eager.metrics.items():
        if key not in timing:
            np.testing.assert_allclose(lazy.metrics[key], value, rtol=1e-9, atol=1e-15)
    names, matrix = lazy.trajectory.columns()  # the CSV reads them
    assert lazy.trajectory.energies.evaluated
    np.testing.assert_array_equal(
        matrix[:, names.index("E_kin")], eager.trajectory.energies["E_kin"]
    )


def test_bad_energies_option_is_refused(run):
    _, _, plant, t, X, U, meta = run
    with pytest.raises(SpecError, match="'sometimes'.*allowed: 'lazy', 'eager'"):
        trajectory_from_states(plant, t, X, U, meta, compiled=True, energies="sometimes")
