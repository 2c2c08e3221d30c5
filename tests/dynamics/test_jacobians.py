"""The Jacobian kept once per lifted model structure gives the per-model Jacobian to the last
bit."""

from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest
from support import DATA

import flexctrl as fc
from flexctrl.dynamics.build import build_model
from flexctrl.dynamics.jacobians import SHARED, jacobian_function
from flexctrl.dynamics.parametric import FROM_LIFTED
from flexctrl.linear import Linearizer, equilibrium


@pytest.fixture(scope="module")
def arm():
    return fc.load_arm(DATA / "models" / "subedi3link.toml")


def _at(fun, model, seed=0):
    rng = np.random.default_rng(seed)
    return [
        np.array(m, dtype=float)
        for m in fun(rng.uniform(-0.2, 0.2, model.n_x), rng.uniform(-5, 5, model.n_u))
    ]


def test_one_structure_serves_every_configuration_with_the_same_bits(arm):
    SHARED.clear()
    FROM_LIFTED.clear()  # what the kept lifts of earlier tests hold
    for fidelity, poses in (
        ("amm:2", ([0, 0, 0], [0, 1.2, -0.7], [0, 1.57, 0])),
        ("amm:3", ([0, 0, 0], [0, -0.5, 1.0])),
    ):
        for q in poses:
            model = build_model(arm, fidelity, reference_q=q)
            for value in (False, True):
                own = _at(jacobian_function(model, value=value, inputs=True), model)
                kept = _at(jacobian_function(model, value=value, inputs=True, shared=True), model)
                assert len(own) == len(kept) == 2 + value
                assert all(np.array_equal(a, b) for a, b in zip(own, kept)), (fidelity, q, value)
    assert len(SHARED._built) == 4  # one per fidelity and output recipe, whatever the pose


def test_the_linearizer_takes_the_kept_jacobian_and_its_sensors_own(arm):
    model = build_model(arm, "amm:2", reference_q=[0, 0.8, -0.3])
    SHARED.clear()
    FROM_LIFTED.clear()  # what the kept lifts of earlier tests hold
    lin = Linearizer(model, ("joints", "strain"))
    assert len(SHARED._built) == 1
    op = equilibrium(model, np.array([0.1, 0.8, -0.3]))
    A, B, C, D = lin.matrices(op)
    own = jacobian_function(model, inputs=True, outputs=lin.sensors.function)
    for a, b in zip((A, B, C, D), own(op.x, op.u)):
        assert np.array_equal(a, np.array(b, dtype=float))
    assert C.shape == (lin.sensors.n_y, model.n_x) and np.any(C != 0) and np.any(A != 0)


def test_dynamics_without_constants_to_lift_keep_their_own_jacobian():
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u")
    model = SimpleNamespace(
        functions={"f": ca.Function("f", [x, u], [ca.vertcat(x[1], u - x[0] * x[1])])}, n_x=2, n_u=1
    )
    SHARED.clear()
    FROM_LIFTED.clear()  # what the kept lifts of earlier tests hold
    A, B = _at(jacobian_function(model, inputs=True, shared=True), model)
    assert len(SHARED._built) == 0
    rng = np.random.default_rng(0)
    x0, _u0 = rng.uniform(-0.2, 0.2, 2), rng.uniform(-5, 5, 1)  # as _at draws them
    assert np.array_equal(A, [[0.0, 1.0], [-x0[1], -x0[0]]]) and np.array_equal(B, [[0.0], [1.0]])


def test_the_kept_jacobian_of_an_sx_lift_is_an_sx_function_with_the_per_model_bits(arm):
    """The kept Jacobian differentiates the SX lift itself and gives the per-model values."""
    SHARED.clear()
    FROM_LIFTED.clear()  # what the kept lifts of earlier tests hold
    for fidelity in ("amm:1", "amm:4"):
        model = build_model(arm, fidelity, reference_q=[0, 1.2, -0.7])
        for seed in range(3):
            kept = _at(jacobian_function(model, value=True, inputs=True, shared=True), model, seed)
            own = _at(jacobian_function(model, value=True, inputs=True), model, seed)
            assert all(np.array_equal(a, b) for a, b in zip(kept, own)), (fidelity, seed)
    assert [f.is_a("SXFunction") for f in SHARED._built.values()] == [True, True]
