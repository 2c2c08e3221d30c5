"""The Kalman filter of the shipped output-feedback controllers converges on the nominal plant from a wrong start."""

from __future__ import annotations

import numpy as np
import pytest
from support import DATA

import flexctrl as fc

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
