"""The NMPC with a reduced prediction model: the loop stays stable; one library per structure."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sl

from flexctrl import linear as L
from flexctrl.control.lqr import build_sensors, linear_plant
from flexctrl.control.nmpc.interval import interval_functions
from flexctrl.control.nmpc.prediction_model import coupled_basis, modal_map
from flexctrl.scenes.cache import SceneCache
from flexctrl.scenes.loop_setup import build_loop
from flexctrl.scenes.model_files import load_model
from flexctrl.spec.controller_settings import SensorSettings
from flexctrl.spec.scene import load_scene

SCENE = "studies/scenes/move_joint1_30deg.toml"  # horizontal plane, 2 kg, target (30, 0, 0) deg


def _setup(*overrides):
    scene = load_scene(SCENE)
    return build_loop(scene, "controllers/nmpc.toml", ["compile=false", *overrides], SceneCache())


def _modes(mass, a_lin):
    N = mass.shape[0]
    K = mass @ -a_lin[N:, :N]
    w2, Phi = sl.eigh(0.5 * (K + K.T), mass)
    return np.sqrt(np.clip(w2, 0.0, None)), Phi


@pytest.fixture(scope="module")
def reduced_setups():
    return {
        mp: _setup("prediction_modes=1", f"prediction_basis={basis}", f"prediction_map={mp}")
        for mp, basis in (("modal", "coupled"), ("select", "assumed"))
    }


def _gain_on_design_state(ctrl):
    pb = ctrl.problem
    K = pb.Su[:, None] * pb.K / pb.Sx[None, :]
    T = ctrl.prediction.state_map
    if T is None:
        T = np.eye(ctrl.op.x.size)[ctrl.keep]
    return K @ T


def test_coupled_basis_keeps_the_slowest_frequencies_the_assumed_modes_do_not(reduced_setups):
    # undamped frequencies of the linearisations at the target (the damping, zeta per assumed mode,
    # is not
    # proportional to the coupled modes, so the damped eigenvalues differ by ~0.2 %)
    def frequencies(ctrl, model, x_op):
        n = model.n_q
        return _modes(
            np.asarray(model.functions["M"](x_op[:n]), dtype=float),
            np.asarray(ctrl.sys.A, dtype=float),
        )[0]

    setup = reduced_setups["modal"]
    c = setup.controller
    want = frequencies(c.plant, setup.plant, c.op.x)[3:6]  # the three slowest elastic modes, rad/s
    got = frequencies(c.prediction_plant, c.prediction.model, c.pred_op.x)[3:]
    np.testing.assert_allclose(got, want, rtol=1e-9)
    a = reduced_setups["select"].controller
    off = frequencies(a.prediction_plant, a.prediction.model, a.pred_op.x)[3:]
    assert np.max(np.abs(off / want - 1.0)) > 0.2  # the first assumed modes: 343 against 268 rad/s


def test_modal_map_removes_the_fast_modes_and_keeps_the_slow_ones():
    model = load_model("models/subedi3link.toml", fidelity="amm:2")
    op = L.equilibrium(model, np.radians([80.0, -10.0, -10.0]))  # with gravity
    plant = linear_plant(model, op, build_sensors(model, SensorSettings(), op), 0.01)
    A = np.asarray(plant.sys.A, dtype=float)
    mass = np.asarray(model.functions["M"](op.x[:9]), dtype=float)
    _, Phi = _modes(mass, A)
    for P in (coupled_basis(mass, A, 3, 3), np.eye(9)[:, [0, 1, 2, 3, 5, 7]]):
        T = modal_map(mass, A, P)
        Tq = T[:6, :9]
        assert np.max(np.abs(Tq @ Phi[:, 6:])) < 1e-9 * np.max(np.abs(Tq @ Phi[:, :6]))
        np.testing.assert_allclose(T[6:, 9:], Tq, rtol=0, atol=0)  # rates map as the coordinates
    # the coupled basis spans the slow modes up to the gravity-stiffened rigid ones' elastic parts
    P = coupled_basis(mass, A, 3, 3)
    Tq = modal_map(mass, A, P)[:6, :9]
    flexible = Phi[:, 3:6]
    assert np.linalg.norm(P @ Tq @ flexible - flexible) < 1e-2 * np.linalg.norm(flexible)


def test_modal_map_is_what_keeps_the_tuned_reduced_loop_stable(reduced_setups):
    # the sampled state-feedback loop of the 18-state arm under the reduced design's gain, about the
    # target
    radius = {}
    for name, setup in reduced_setups.items():
        c = setup.controller
        radius[name] = float(
            np.max(np.abs(np.linalg.eigvals(c.plant.Ad - c.plant.Bd @ _gain_on_design_state(c))))
        )
    assert radius["modal"] < 0.99 < 1.0 < radius["select"]


def test_the_reduced_nmpc_regulates_the_full_arm():
    setup = _setup("prediction_modes=1")
    ctrl = setup.controller
    assert ctrl.problem.n == 12 and ctrl.substeps == 2 and ctrl.prediction.state_map is not None
    F, _ = interval_functions(setup.plant, 0.01, 9, None)  # the plant: all 18 states
    op = ctrl.op
    x = op.x.copy()
    x[:3] += np.radians([3.0, -2.0, 2.0])
    ctrl.set_reference(None)  # regulation to the target
    ctrl.reset()
    start = np.max(np.abs(x[:3] - op.x[:3]))
    u = op.u
    elastic = []
    for k in range(150):
        u = ctrl.step(0.01 * k, setup.sensors.measure(x, u))
        x = np.asarray(F(x, u), dtype=float).ravel()
        elastic.append(np.max(np.abs(x[3:9])))
    assert ctrl.stats.summary()["fallbacks"] == 0
    assert np.max(np.abs(x[:3] - op.x[:3])) < 0.05 * start
    assert elastic[-1] < 0.1 * max(elastic)  # the vibration the move excites dies out


def test_reduced_prediction_settings_are_checked():
    from flexctrl.errors import SpecError
    from flexctrl.spec.controller_reader import controller_from_document

    with pytest.raises(SpecError, match="nmpc_bad.toml.*prediction_basis.*coupled"):
        controller_from_document({"kind": "nmpc", "prediction_basis": "modal"}, "nmpc_bad.toml")
    with pytest.raises(SpecError, match="nmpc_bad.toml.*prediction_map"):
        controller_from_document({"kind": "nmpc", "prediction_map": "coupled"}, "nmpc_bad.toml")
    with pytest.raises(SpecError, match="nmpc_bad.toml.*jacobian_every"):
        controller_from_document({"kind": "nmpc", "jacobian_every": 0}, "nmpc_bad.toml")
    settings = controller_from_document(
        {"kind": "nmpc", "prediction_modes": 1, "jacobian_every": 3}, "nmpc.toml"
    )
    assert (settings.prediction_basis, settings.prediction_map, settings.jacobian_every) == (
        "coupled",
        "modal",
        3,
    )


def test_one_compiled_linearization_serves_every_configuration_of_the_reduced_prediction():
    # the coupled basis's values coincide with other constants at some configurations; lifted per
    # use,
    # the generated code (its cache key) is the same at the straight and the folded arm
    from flexctrl.sim.compile import cache_key

    keys = set()
    for q in ("[0.0,0.0,0.0]", "[0.0,90.0,-90.0]"):
        setup = build_loop(
            load_scene(SCENE, [f"initial.q={q}"]),
            "controllers/nmpc.toml",
            ["compile=false"],
            SceneCache(),
        )
        keys.add(cache_key(setup.controller.functions["linmap"], [], "cc"))
    assert len(keys) == 1


def test_a_configuration_of_the_same_structure_reuses_the_linearization_and_gets_the_same_numbers():
    # the horizon linearisation is memoised by the content of the lifted f and the recipe: a second
    # configuration reuses it; built afresh (memo emptied) it gives the same shooting ends and
    # Jacobians
    from flexctrl.control.nmpc import interval as nmpc_interval

    def setup(q):
        return build_loop(
            load_scene(SCENE, [f"initial.q={q}"]),
            "controllers/nmpc.toml",
            ["compile=false"],
            SceneCache(),
        ).controller

    setup("[0.0,0.0,0.0]")
    reused = setup("[0.0,90.0,-90.0]")
    assert reused.functions["build"]["reused"] is True
    nmpc_interval._BUILT.clear()
    fresh = setup("[0.0,90.0,-90.0]")
    assert fresh.functions["build"]["reused"] is False
    lay, rng = fresh.layout, np.random.default_rng(3)
    Z, V = 0.1 * rng.standard_normal((lay.n, lay.N)), 0.1 * rng.standard_normal((lay.m, lay.N))
    p = fresh.functions["params"]
    np.testing.assert_array_equal(reused.functions["params"], p)
    for a, b in zip(reused.functions["linmap"](Z, V, p), fresh.functions["linmap"](Z, V, p)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    x = fresh.op.x.copy()
    x[0] += np.radians(2.0)  # off the target: the first sample's RTI does work
    y = fresh.sensors.measure(x, fresh.op.u)
    u = fresh.step(0.0, y)
    assert np.max(np.abs(u - fresh.op.u)) > 1.0  # N m: a real correction, not the holding torque
    np.testing.assert_array_equal(reused.step(0.0, y), u)
