"""A closed loop's energies are evaluated when first read, and are the model's energies.

The tip and deflections come from a map without the energies (its own compiled code), so
they agree with the full output map to round-off, not to the bit; the energies, when read,
agree with the model's own ``energies`` Function evaluated state by state.
"""

import copy
import dataclasses
import pickle

import numpy as np
import pytest

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


def _model_energies(plant, X):
    """The model's ``energies`` Function at every state, in CasADi's virtual machine."""
    q, qd = X[:, : plant.n_q].T, X[:, plant.n_q :].T
    values = mapped(plant, "energies", X.shape[0], q, qd)
    return {name: np.array(v, dtype=float).ravel() for name, v in zip(ENERGY_NAMES, values)}


@pytest.mark.parametrize("compiled", [True, False])
def test_energies_read_later_are_the_models_energies(run, compiled):
    _, _, plant, t, X, U, meta = run
    lazy = trajectory_from_states(plant, t, X, U, meta, compiled=compiled)
    assert isinstance(lazy.energies, LazyEnergies) and not lazy.energies.evaluated
    assert list(lazy.energies) == list(ENERGY_NAMES) and len(lazy.energies) == 4
    assert lazy.energies.evaluated is False  # iterating over the names computes nothing
    expected = _model_energies(plant, X)
    assert np.ptp(expected["E_kin"]) > 0  # a moving arm: the comparison compares something
    for name in ("E_kin", "E_el", "E_grav"):
        scale = max(np.max(np.abs(expected[name])), 1e-12)
        np.testing.assert_allclose(lazy.energies[name], expected[name], rtol=0, atol=1e-12 * scale)
    assert lazy.energies.evaluated
    np.testing.assert_array_equal(
        lazy.energies["E_total"],
        lazy.energies["E_kin"] + lazy.energies["E_el"] + lazy.energies["E_grav"],
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
    scene, cache, plant, *_ = run
    result = run_closed_loop_scene(scene, cache=cache, on_divergence="record")
    assert not result.trajectory.energies.evaluated
    names, matrix = result.trajectory.columns()  # the CSV reads them
    assert result.trajectory.energies.evaluated
    expected = _model_energies(plant, result.trajectory.states)["E_kin"]
    np.testing.assert_allclose(
        matrix[:, names.index("E_kin")], expected, rtol=0, atol=1e-12 * np.max(np.abs(expected))
    )
