"""Joint PD: automatic gains, gravity compensation, the torque filter light hubs need, a move."""

from __future__ import annotations

import math

import numpy as np

from flexctrl import linear as L
from flexctrl.control import design
from flexctrl.control.nmpc.controller import interval_functions
from flexctrl.spec.controller_settings import (
    PDSettings,
)

TARGET = np.radians([80.0, -10.0, -10.0])


def test_pd_holds_the_equilibrium_and_has_automatic_gains(arm3, op3):
    ctrl = design(arm3, op3, PDSettings(bandwidth=2.0, damping=0.7, torque_filter=0.0))
    inertia = np.diag(arm3.mass_matrix(op3.q))[:3]
    w = 2 * math.pi * 2.0
    np.testing.assert_allclose(ctrl.kp, inertia * w**2)
    np.testing.assert_allclose(ctrl.kd, 2 * 0.7 * inertia * w)
    ctrl.reset()
    y = np.r_[op3.joints, np.zeros(3)]
    np.testing.assert_allclose(ctrl.step(0.0, y), op3.u)
    # a large error saturates and is counted
    u = ctrl.step(0.001, np.r_[op3.joints - 1.0, np.zeros(3)])
    np.testing.assert_allclose(np.abs(u), ctrl.limits)
    assert ctrl.stats.saturated == 1


def test_pd_with_measured_gravity_compensation_matches_static_torque(arm3, op3):
    ctrl = design(
        arm3,
        op3,
        PDSettings(gravity="measured", kp=(0.0, 0.0, 0.0), kd=(0.0, 0.0, 0.0), saturate=False),
    )
    q = TARGET + np.radians([5.0, -3.0, 2.0])
    tau = ctrl.step(0.0, np.r_[q, np.zeros(3)])
    expected = arm3.gravity(np.r_[q, op3.q[3:]])[:3]  # K has no joint rows
    np.testing.assert_allclose(tau, expected, rtol=1e-10)


def _sampled_pd_radius(model, op, settings):
    """Spectral radius of the ZOH-sampled linear loop with the filtered PD, built independently."""
    from flexctrl.control.pd import pd_gains

    sysd = L.discretize(L.linearize(model, op, ("state",)), settings.sample_time)
    A, B = np.asarray(sysd.A), np.asarray(sysd.B)
    kp, kd = pd_gains(model, op, settings)
    N = model.n_q
    K = np.zeros((3, 2 * N))
    K[range(3), range(3)], K[range(3), N + np.arange(3)] = kp, kd
    a = (
        math.exp(-2 * math.pi * settings.torque_filter * settings.sample_time)
        if settings.torque_filter
        else 0.0
    )
    # f_k = a f_{k-1} - (1 - a) K x_k;  x_{k+1} = A x_k + B f_k   (state (x_k, f_{k-1}))
    Acl = np.block([[A - (1 - a) * B @ K, a * B], [-(1 - a) * K, a * np.eye(3)]])
    return float(np.max(np.abs(np.linalg.eigvals(Acl))))


def test_sampled_pd_needs_the_torque_filter_on_light_hubs(damped3):
    op = L.equilibrium(damped3, TARGET)
    assert (
        _sampled_pd_radius(damped3, op, PDSettings(torque_filter=0.0)) > 2.0
    )  # unfiltered: unstable
    assert _sampled_pd_radius(damped3, op, PDSettings()) < 1.0  # the default filter: stable


def test_pd_moves_the_nonlinear_arm_to_the_target(damped3):
    op = L.equilibrium(damped3, TARGET)
    ctrl = design(damped3, op, PDSettings())
    F, _ = interval_functions(damped3, ctrl.sample_time, 3, "frozen")
    ctrl.reset()
    x = op.x.copy()
    x[:3] += np.radians([1.0, 1.0, -1.0])
    errors = []
    for k in range(3000):
        y = ctrl.sensors.measure(x, ctrl.u_previous)
        x = np.array(F(x, ctrl.step(ctrl.sample_time * k, y)), dtype=float).ravel()
        errors.append(np.max(np.abs(x[:3] - op.x[:3])))
    assert errors[-1] < 0.2 * errors[0]
    assert np.all(np.isfinite(x))
