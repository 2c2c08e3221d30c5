"""The Kalman filter: its gain against python-control and a scalar case, and its convergence."""

from __future__ import annotations

import control
import numpy as np
import pytest
from support import DATA

import flexctrl as fc
from flexctrl.control import design
from flexctrl.control.estimator import kalman_gain
from flexctrl.spec.controller_settings import (
    LQRSettings,
    SensorSettings,
)


def test_kalman_gain_matches_python_control_dlqe(arm3, op3):
    ctrl = design(arm3, op3, LQRSettings(sensors=SensorSettings(outputs=("joints", "strain"))))
    kf = ctrl.observer
    # python-control's dlqe on the same filter in balanced coordinates x = T x', y = r y'
    # (unbalanced, the QZ reordering inside the DARE solver fails for this arm)
    t = np.sqrt(np.diag(kf.W))
    r = np.sqrt(np.diag(kf.R))
    As, Cs = kf.A * t[None, :] / t[:, None], kf.C * t[None, :] / r[:, None]
    Ws, Rs = kf.W / np.outer(t, t), kf.R / np.outer(r, r)
    L_s, _P, _E = control.dlqe(As, np.eye(As.shape[0]), Cs, Ws, Rs)
    L_pc = t[:, None] * L_s / r[None, :]
    # python-control gives the predictor gain L = A M of the same filter
    np.testing.assert_allclose(kf.A @ kf.M, L_pc, rtol=1e-4, atol=1e-6 * np.max(np.abs(L_pc)))
    assert np.max(np.abs(kf.poles)) < 1.0


def test_kalman_gain_of_a_scalar_system_is_analytic():
    # x+ = a x + w, y = x + v: P = a^2 P - a^2 P^2/(P + r) + q; M = P / (P + r)
    a, q, r = 0.9, 0.5, 2.0
    M, P = kalman_gain(np.array([[a]]), np.array([[1.0]]), np.array([[q]]), np.array([[r]]))
    p = P[0, 0]
    assert p == pytest.approx(a * a * p - a * a * p * p / (p + r) + q)
    assert M[0, 0] == pytest.approx(p / (p + r))


TARGET = np.radians([30.0, 0.0, 0.0])


@pytest.mark.parametrize("name", ["lqr", "lqg", "mpc"])
def test_estimate_converges_from_a_wrong_initial_state_at_the_predicted_rate(name):
    model = fc.load_model(
        DATA / "models" / "subedi3link.toml",
        payload=2.0,
        fidelity="amm:2",
        gravity=[0.0, 0.0],
        overrides={f"links[{i}].damping_ratio": 0.005 for i in (1, 2, 3)},
    )
    op = fc.equilibrium(model, TARGET)
    ctrl = fc.design(model, op, fc.load_controller(DATA / "controllers" / f"{name}.toml"))
    estimator = ctrl.observer
    assert not ctrl.sensors.full_state and hasattr(estimator, "M")
    wrong = np.zeros(model.n_x)
    wrong[:3] = np.radians([2.0, -1.0, 1.5])  # joints
    wrong[3] = 5e-3  # the first modal coordinate, m
    estimator.reset()
    estimator.dx = wrong.copy()
    # the arm at rest at the target, measured by the controller's own sensors on the nonlinear model
    y = ctrl.sensors.evaluate(op.x, op.u)
    errors = []
    for _ in range(400):
        errors.append(np.linalg.norm(estimator.estimate(y, op.u) - op.x))
    errors = np.array(errors)
    rate = np.max(np.abs(estimator.poles))
    assert rate < 1.0
    assert errors[-1] < 1e-6 * errors[0]
    # the decay over the last 100 samples is no slower than the slowest estimator pole allows
    assert errors[-1] <= errors[-101] * rate**100 * 10
