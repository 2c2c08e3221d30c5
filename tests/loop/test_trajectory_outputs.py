"""A closed loop's trajectory outputs: the tip and deflections, and energies evaluated when read.

The tip and deflections come from the plant's output map without the energies (its own
compiled code), so they agree with the full output map to round-off, not to the bit; the
energies, when read, come from the full map itself, so they are its values to the bit, and
the model's own energies Function's to round-off.
"""

import copy
import dataclasses
import pickle

import numpy as np
import pytest

from flexctrl.loop.plant_step import output_map
from flexctrl.loop.sampled import integrate_closed_loop, tip_positions, trajectory_from_states
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


def mapped(model, name, count, *args):
    """The model's own Function ``name`` over ``count`` columns, in CasADi's virtual machine."""
    return [np.array(v, dtype=float) for v in model.functions[name].map(count)(*args)]


def test_energies_are_evaluated_when_read_and_are_the_full_maps(run):
    _, _, plant, t, X, U, meta = run
    trajectory = trajectory_from_states(plant, t, X, U, meta)
    energies = trajectory.energies
    assert isinstance(energies, LazyEnergies) and not energies.evaluated
    assert list(energies) == list(ENERGY_NAMES) and len(energies) == 4
    assert energies.evaluated is False  # iterating over the names computes nothing
    full = evaluate(output_map(plant, t.size), X)[0]
    for k, name in enumerate(("E_kin", "E_el", "E_grav")):
        np.testing.assert_array_equal(energies[name], full[:, k])
    assert energies.evaluated
    assert np.ptp(energies["E_kin"]) > 0  # a moving arm: the comparison compares something
    np.testing.assert_array_equal(energies["E_total"], full[:, 0] + full[:, 1] + full[:, 2])
    q, qd = X[:, : plant.n_q].T, X[:, plant.n_q :].T
    own = mapped(plant, "energies", t.size, q, qd)
    for name, values in zip(("E_kin", "E_el", "E_grav"), own):
        scale = max(np.max(np.abs(values)), 1e-12)
        assert np.max(np.abs(energies[name] - values.ravel())) <= 1e-12 * scale
    with pytest.raises(KeyError):
        energies["E_wrong"]


def test_tip_rows_come_from_the_map_without_energies(run):
    _, _, plant, t, X, U, meta = run
    full = evaluate(output_map(plant, t.size), X)[0]
    kinematic = evaluate(output_map(plant, t.size, energies=False), X)[0]
    assert kinematic.shape == (t.size, full.shape[1] - 3)
    np.testing.assert_allclose(
        kinematic, full[:, 3:], rtol=0, atol=1e-14 * np.max(np.abs(full[:, 3:5]))
    )
    trajectory = trajectory_from_states(plant, t, X, U, meta)
    np.testing.assert_array_equal(trajectory.tip, kinematic[:, :2])
    np.testing.assert_array_equal(trajectory.deflections, kinematic[:, 2:])


def test_lazy_energies_are_computed_once_when_first_read():
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
    """The fidelity chooser's tip paths: the compiled map's, within round-off of the model's tip."""
    _, _, plant, t, X, U, meta = run
    tip = tip_positions(plant, X[::7])
    np.testing.assert_array_equal(tip, trajectory_from_states(plant, t, X, U, meta).tip[::7])
    vm = mapped(plant, "tip", tip.shape[0], X[::7, : plant.n_q].T, X[::7, plant.n_q :].T)[0].T
    assert np.max(np.abs(tip - vm)) <= 1e-14 * np.max(np.abs(vm))


def test_copies_and_pickles_are_plain_dicts(run):
    _, _, plant, t, X, U, meta = run
    lazy = trajectory_from_states(plant, t, X, U, meta)
    for other in (copy.deepcopy(lazy.energies), pickle.loads(pickle.dumps(lazy.energies))):
        assert type(other) is dict and list(other) == list(ENERGY_NAMES)
        for name in ENERGY_NAMES:
            np.testing.assert_array_equal(other[name], lazy.energies[name])


def test_the_scene_metrics_do_not_read_the_energies(run):
    scene, cache, *_ = run
    result = run_closed_loop_scene(scene, cache=cache, on_divergence="record")
    assert not result.trajectory.energies.evaluated
    names, matrix = result.trajectory.columns()  # the CSV reads them
    assert result.trajectory.energies.evaluated
    full = evaluate(output_map(result.model, result.trajectory.time.size), result.trajectory.states)
    np.testing.assert_array_equal(matrix[:, names.index("E_kin")], full[0][:, 0])
