"""Raw ``Q``, ``R``: the LQR gain of ``control.dlqr`` on the discretised design model, the MPC's
unconstrained move the same, the Bryson form reproduced, bad matrices named."""

from __future__ import annotations

import dataclasses

import control
import numpy as np
import pytest
from support import DATA

import flexctrl as fc
from flexctrl.control.lqr import weight_matrices
from flexctrl.errors import SpecError
from flexctrl.spec.controller_reader import load_controller
from flexctrl.spec.controller_settings import LQRSettings, MPCSettings

DAMPED = [f"links[{i}].damping_ratio=0.005" for i in (1, 2, 3)]


@pytest.fixture(scope="module")
def arm():
    model = fc.load_model(
        "subedi3link", payload=2.0, fidelity="amm:1", gravity=[0.0, 0.0], overrides=DAMPED
    )
    return model, fc.equilibrium(model, np.radians([30.0, 0.0, 0.0]))


def _weights(n_x: int, n_u: int):
    """A full (non-diagonal) positive definite ``Q`` and ``R`` of sensible magnitudes."""
    rng = np.random.default_rng(3)
    scale = np.r_[np.full(3, 100.0), np.full(n_x // 2 - 3, 300.0), np.full(n_x // 2, 1.0)]
    M = rng.standard_normal((n_x, n_x)) * 0.2 + np.eye(n_x)
    Q = np.diag(scale) @ (M.T @ M) @ np.diag(scale)
    N = rng.standard_normal((n_u, n_u)) * 0.2 + np.eye(n_u)
    R = 1e-2 * (N.T @ N)
    return 0.5 * (Q + Q.T), 0.5 * (R + R.T)


def _dlqr(model, op, Ts, Q, R):
    """``control.dlqr`` on the design model's linearisation, discretised here by python-control."""
    sysd = control.sample_system(fc.linearize(model, op), Ts, method="zoh")
    K, _S, _E = control.dlqr(sysd.A, sysd.B, Q, R)
    return np.asarray(K)


def test_raw_q_r_give_the_gain_of_control_dlqr(arm):
    model, op = arm
    Q, R = _weights(model.n_x, model.n_u)
    ctrl = fc.design(model, op, LQRSettings(sample_time=0.01, Q=Q, R=R))
    assert ctrl.state_names == tuple(fc.linearize(model, op).state_labels)
    K = _dlqr(model, op, 0.01, Q, R)
    assert np.max(np.abs(ctrl.K - K)) <= 1e-8 * np.max(np.abs(K))
    # and the gain is not the Bryson one (the raw matrices were used)
    bryson = fc.design(model, op, LQRSettings(sample_time=0.01))
    assert np.max(np.abs(bryson.K - K)) > 1e-2 * np.max(np.abs(K))


def test_the_mpc_moves_as_the_raw_lqr_when_no_constraint_is_active(arm):
    model, op = arm
    Q, R = _weights(model.n_x, model.n_u)
    K = _dlqr(model, op, 0.01, Q, R)
    settings = MPCSettings(sample_time=0.01, horizon=15, soft="none", Q=Q, R=R)
    for formulation in ("sparse", "condensed"):
        mpc = fc.design(model, op, dataclasses.replace(settings, formulation=formulation))
        assert np.max(np.abs(mpc.K - K)) <= 1e-8 * np.max(np.abs(K))
        np.testing.assert_allclose(mpc.unconstrained_gain(), mpc.K, rtol=1e-6, atol=1e-9)


def test_a_diagonal_list_and_the_bryson_matrices_reproduce_the_bryson_design(arm):
    model, op = arm
    Qb, Rb = weight_matrices(model, fc.Weights())
    bryson = fc.design(model, op, LQRSettings())
    as_lists = fc.design(model, op, LQRSettings(Q=np.diag(Qb).tolist(), R=np.diag(Rb).tolist()))
    as_matrices = fc.design(model, op, LQRSettings(Q=Qb, R=Rb))
    np.testing.assert_array_equal(as_lists.K, bryson.K)
    np.testing.assert_array_equal(as_matrices.K, bryson.K)


@pytest.mark.parametrize(
    "kwargs, key, fragment",
    [
        (dict(Q=[[1.0, 2.0], [0.0, 1.0]]), "Q", "not symmetric"),
        (dict(Q=[[1.0, 2.0], [2.0, 1.0]]), "Q", "indefinite"),
        (dict(Q=[1.0, -1.0]), "Q", "indefinite"),
        (dict(R=[1.0, 0.0, 1.0]), "R", "positive definite"),
        (dict(Q=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), "Q", "shape (2, 3)"),
        (dict(R=[[1.0, float("nan")], [0.0, 1.0]]), "R", "nan"),
        (dict(Q="big"), "Q", "square matrix"),
    ],
)
def test_bad_matrices_are_refused_when_built(kwargs, key, fragment):
    for cls in (LQRSettings, MPCSettings):
        with pytest.raises(SpecError) as info:
            cls(**kwargs)
        assert info.value.key == key and fragment in str(info.value), str(info.value)


def test_a_matrix_of_the_wrong_size_for_the_model_names_the_states(arm):
    model, op = arm
    with pytest.raises(SpecError) as info:
        fc.design(model, op, LQRSettings(Q=np.eye(6)))
    assert info.value.key == "Q" and "(12, 12)" in str(info.value) and "dqf31" in str(info.value)
    with pytest.raises(SpecError) as info:
        fc.design(model, op, MPCSettings(R=np.eye(2)))
    assert info.value.key == "R" and "(3, 3)" in str(info.value)


def test_files_take_a_matrix_or_its_diagonal_and_refuse_both_forms(tmp_path):
    path = tmp_path / "lqr.toml"
    path.write_text('kind = "lqr"\n[weights]\nQ = [1.0, 2.0]\nR = [[2.0, 0.5], [0.5, 1.0]]\n')
    s = load_controller(path)
    assert s.Q == ((1.0, 0.0), (0.0, 2.0)) and s.R == ((2.0, 0.5), (0.5, 1.0))
    path.write_text('kind = "mpc"\n[weights]\nQ = [1.0, 2.0]\njoint_deg = 0.5\n')
    with pytest.raises(SpecError) as info:
        load_controller(path)
    assert "weights.Q" in str(info.value) and "'joint_deg'" in str(info.value)
    path.write_text('kind = "lqr"\n[weights]\nR = [[1.0, 2.0], [0.0, 1.0]]\n')
    with pytest.raises(SpecError) as info:
        load_controller(path)
    assert "weights.R" in str(info.value) and "not symmetric" in str(info.value)
    path.write_text('kind = "nmpc"\n[weights]\nQ = [1.0]\n')
    with pytest.raises(SpecError, match="weights.Q"):
        load_controller(path)
    assert load_controller(DATA / "controllers" / "lqr.toml").Q is None
