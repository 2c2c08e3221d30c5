"""The Jacobian of f through one factorisation of M (flexctrl.control.nmpc.jacobian) against CasADi's."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from flexctrl.control.nmpc.controller import design_nmpc
from flexctrl.control.nmpc.jacobian import factored_dynamics
from flexctrl.scenes.model_files import load_model
from flexctrl.spec.controller_settings import NMPCSettings


@pytest.fixture(scope="module")
def arm():
    return load_model("models/subedi3link.toml", fidelity="amm:2")


def _symbolic(model):
    x, u = ca.SX.sym("x", model.n_x), ca.SX.sym("u", model.n_u)
    f = model.functions["f"](x, u)
    return ca.Function("J", [x, u], [f, ca.jacobian(f, x), ca.jacobian(f, u)])


def test_factored_jacobian_equals_casadis_on_random_states(arm):
    f, f_jac, const = factored_dynamics(arm)
    reference = _symbolic(arm)
    rng = np.random.default_rng(7)
    N = arm.n_q
    for _ in range(8):
        x = np.r_[
            rng.uniform(-np.pi, np.pi, arm.n_u),
            0.02 * rng.standard_normal(N - arm.n_u),
            rng.standard_normal(arm.n_u),
            0.5 * rng.standard_normal(N - arm.n_u),
        ]
        u = 30.0 * rng.standard_normal(arm.n_u)
        want = [np.array(v, dtype=float) for v in reference(x, u)]
        got = [np.array(v, dtype=float) for v in f_jac(x, u, const)]
        for name, w, g in zip(("f", "f_x", "f_u"), want, got):
            assert np.max(np.abs(g - w)) <= 1e-9 * np.max(np.abs(w)), name
        assert np.allclose(
            np.array(f(x, u, const), dtype=float),
            want[0],
            rtol=0,
            atol=1e-9 * np.max(np.abs(want[0])),
        )
    # the elastic rows of f_x are not trivially small: the comparison is meaningful
    assert np.max(np.abs(want[1][N:, :N])) > 1.0


def test_a_model_whose_f_is_not_the_mass_matrix_solve_is_rejected(arm):
    x, u = ca.SX.sym("x", arm.n_x), ca.SX.sym("u", arm.n_u)
    other = ca.Function("f", [x, u], [1.01 * arm.functions["f"](x, u)], ["x", "u"], ["xdot"])
    wrong = dataclasses.replace(arm, functions={**arm.functions, "f": other})
    with pytest.raises(ValueError, match="does not reproduce its f"):
        factored_dynamics(wrong)


def test_jacobian_choice_is_checked(arm):
    with pytest.raises(
        ValueError, match="jacobian 'numeric' is not allowed; allowed: 'symbolic', 'factored'"
    ):
        design_nmpc(arm, None, NMPCSettings(), jacobian="numeric")
