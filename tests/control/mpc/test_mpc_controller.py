"""Linear MPC: unconstrained = LQR = closed-form QP; hard torque limits; soft limits; fallbacks.

Soft limits never make the QP infeasible.
"""

from __future__ import annotations

import numpy as np
import pytest

from flexctrl.control import design
from flexctrl.control.lqr import weight_matrices
from flexctrl.spec.controller_settings import MPCSettings, OSQPSettings

TARGET = np.radians([80.0, -10.0, -10.0])
TIGHT = OSQPSettings(eps_abs=1e-10, eps_rel=1e-10, max_iter=20000, polishing=True)


def closed_form_first_move(Ad, Bd, Q, R, P, N, dx0):
    """Minimise sum x'Qx + u'Ru + x_N'P x_N s.t. x_{k+1} = A x_k + B u_k: one KKT solve."""
    n, m = Bd.shape
    nz = N * (n + m)  # w = [u_0..u_{N-1}, x_1..x_N]
    H = np.zeros((nz, nz))
    for k in range(N):
        H[k * m : (k + 1) * m, k * m : (k + 1) * m] = R
        xs = N * m + k * n
        H[xs : xs + n, xs : xs + n] = P if k == N - 1 else Q
    E = np.zeros((N * n, nz))
    e = np.zeros(N * n)
    for k in range(N):
        rows = slice(k * n, (k + 1) * n)
        E[rows, k * m : (k + 1) * m] = -Bd
        E[rows, N * m + k * n : N * m + (k + 1) * n] = np.eye(n)
        if k == 0:
            e[rows] = Ad @ dx0
        else:
            E[rows, N * m + (k - 1) * n : N * m + k * n] = -Ad
    kkt = np.block([[H, E.T], [E, np.zeros((N * n, N * n))]])
    sol = np.linalg.solve(kkt, np.r_[np.zeros(nz), e])
    return sol[:m]


@pytest.mark.parametrize(
    "formulation, backend",
    [("sparse", "osqp"), ("condensed", "osqp"), ("sparse", "hpipm"), ("condensed", "daqp")],
)
def test_unconstrained_first_move_is_lqr_and_closed_form(arm3, op3, formulation, backend):
    settings = MPCSettings(
        horizon=12, soft="none", formulation=formulation, backend=backend, osqp=TIGHT
    )
    ctrl = design(arm3, op3, settings)
    ctrl.reset()
    dx = np.zeros(18)
    dx[:3] = np.radians([0.3, -0.2, 0.25])
    dx[3] = 2e-4
    u = ctrl.step(0.0, op3.x + dx)
    Q, R = weight_matrices(arm3, settings.weights)
    Ad, Bd = ctrl.plant.Ad, ctrl.plant.Bd
    import scipy.linalg

    P = scipy.linalg.solve_discrete_are(Ad, Bd, Q, R)
    K = np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)
    du_lqr = -K @ dx
    du_qp = closed_form_first_move(Ad, Bd, Q, R, P, settings.horizon, dx)
    scale = np.max(np.abs(du_lqr))
    assert np.max(np.abs(du_qp - du_lqr)) < 1e-6 * scale  # DARE terminal cost: finite horizon = LQR
    assert np.max(np.abs(u - op3.u - du_lqr)) < 1e-4 * scale
    assert np.all(np.abs(u) < ctrl.limits)  # constraints inactive indeed
    assert ctrl.stats.fallbacks == []


def _linear_closed_loop(ctrl, dx0, steps):
    Ad, Bd, op = ctrl.plant.Ad, ctrl.plant.Bd, ctrl.op
    dx = dx0.copy()
    us = []
    for k in range(steps):
        u = ctrl.step(k * ctrl.sample_time, op.x + dx)
        us.append(u)
        dx = Ad @ dx + Bd @ (u - op.u)
    return np.array(us), dx


def test_torque_limits_hold_in_a_large_move(arm3, op3):
    ctrl = design(arm3, op3, MPCSettings(soft="none"))
    ctrl.reset()
    dx0 = np.zeros(18)
    dx0[:3] = np.radians([-8.0, 0.0, 0.0])  # recoverable: the arm points up, torque is limited
    assert np.any(np.abs(op3.u - ctrl.K @ dx0) > ctrl.limits)  # LQR would exceed the limits
    us, dx = _linear_closed_loop(ctrl, dx0, 300)
    assert np.all(np.abs(us) <= ctrl.limits * (1 + 1e-6))
    assert np.any(np.abs(us) >= ctrl.limits * 0.999)  # the limits were active
    assert np.max(np.abs(dx[:3])) < np.radians(0.5)
    # the QP itself respects the limits: clipping only removes the solver tolerance
    assert ctrl.stats.clipped_max < 0.01 * np.max(ctrl.limits)


def test_impossible_deflection_limit_stays_feasible_and_records_slack(arm3, op3):
    ctrl = design(arm3, op3, MPCSettings(soft="deflection", deflection_limit=0.0))
    ctrl.reset()
    dx0 = np.zeros(18)
    dx0[:3] = np.radians([1.0, -1.0, 1.0])
    us, _dx = _linear_closed_loop(ctrl, dx0, 20)
    assert np.all(np.abs(us) <= ctrl.limits * (1 + 1e-6))
    # the static deflection at the target alone violates a zero limit; within one sample the
    # arm cannot remove it, so the slack must take (a good part of) it
    static = np.max(np.abs(np.array(arm3.functions["deflection"](op3.q)[0])))
    assert ctrl.stats.slack_max >= 0.25 * static > 0
    assert ctrl.stats.fallbacks == []
    assert sum(v for k, v in ctrl.stats.status.items() if k.startswith("solved")) == 20


def test_deflection_limit_is_respected_when_possible(arm3, op3):
    w = lambda x: np.array(arm3.functions["deflection"](x[:9])[0], dtype=float).ravel()  # noqa: E731
    static = w(op3.x)
    dx0 = np.zeros(18)
    dx0[:3] = np.radians([6.0, -6.0, 6.0])

    def run(ctrl, steps=100):
        """Linear closed loop; the peak |tip deflection| per link (linear output map)."""
        ctrl.reset()
        C = np.hstack(
            [np.array(arm3.functions["deflection"].jacobian()(op3.q, 0, 0)[0]), np.zeros((3, 9))]
        )
        dx, peak = dx0.copy(), np.zeros(3)
        for k in range(steps):
            u = ctrl.step(0.01 * k, op3.x + dx)
            dx = ctrl.plant.Ad @ dx + ctrl.plant.Bd @ (u - op3.u)
            peak = np.maximum(peak, np.abs(static + C @ dx))
        return peak

    free = run(design(arm3, op3, MPCSettings(soft="none")))
    limit = float(np.max(np.abs(static)) + 0.5 * (np.max(free) - np.max(np.abs(static))))
    limited = run(design(arm3, op3, MPCSettings(soft="deflection", deflection_limit=limit)))
    assert np.max(free) > limit
    assert np.max(limited) < limit * 1.02  # held, up to the solver tolerance


def test_forced_osqp_failure_falls_back_to_shifted_plan_then_lqr(arm3, op3):
    ctrl = design(arm3, op3, MPCSettings(soft="none"))
    ctrl.reset()
    dx = np.zeros(18)
    dx[:3] = np.radians([1.0, -1.0, 1.0])
    ctrl.step(0.0, op3.x + dx)
    plan = ctrl.plan()
    ctrl.backend.solver.update_settings(max_iter=1, check_termination=1)
    u1 = ctrl.step(0.01, op3.x + dx)
    np.testing.assert_allclose(u1, plan[1])
    assert ctrl.stats.fallbacks[-1][2] == "shift"
    for k in range(2, ctrl.problem.horizon + 1):
        uk = ctrl.step(0.01 * k, op3.x + dx)
    assert ctrl.stats.fallbacks[-1][2] == "lqr"
    np.testing.assert_allclose(
        uk, np.clip(op3.u - ctrl.K @ dx, -ctrl.limits, ctrl.limits), rtol=1e-9
    )
    assert ctrl.stats.summary()["fallbacks"] == ctrl.problem.horizon
    assert ctrl.stats.status["fallback_shift"] == ctrl.problem.horizon - 1


def test_max_iter_one_from_the_start_uses_lqr(arm3, op3):
    ctrl = design(arm3, op3, MPCSettings(osqp=OSQPSettings(max_iter=1, check_termination=1)))
    ctrl.reset()
    dx = np.zeros(18)
    dx[:3] = np.radians([0.5, -0.5, 0.5])
    u = ctrl.step(0.0, op3.x + dx)
    t, reason, used = ctrl.stats.fallbacks[0]
    assert used == "lqr" and "iter" in reason
    np.testing.assert_allclose(u, np.clip(op3.u - ctrl.K @ dx, -ctrl.limits, ctrl.limits))


def test_hold_fallback_keeps_the_previous_torque(arm3, op3):
    ctrl = design(
        arm3, op3, MPCSettings(fallback="hold", osqp=OSQPSettings(max_iter=1, check_termination=1))
    )
    ctrl.reset()
    u = ctrl.step(0.0, op3.x + 0.001)
    np.testing.assert_allclose(
        u, op3.u
    )  # the previous torque after reset is the target's static torque


def test_sparsity_never_changes_between_steps(arm3, op3):
    ctrl = design(arm3, op3, MPCSettings())
    ctrl.reset()
    A_before = ctrl.backend.A.copy()
    _linear_closed_loop(ctrl, np.r_[np.radians([2.0, -2.0, 2.0]), np.zeros(15)], 10)
    assert (ctrl.backend.A != A_before).nnz == 0
    assert ctrl.stats.summary()["median_iterations"] < 100  # warm starts keep OSQP short


@pytest.mark.parametrize("formulation, backend", [("sparse", "osqp"), ("condensed", "qpoases")])
def test_a_reset_controller_repeats_its_run_to_the_last_digit(arm3, op3, formulation, backend):
    # A study reuses a design across runs and resets it: the solver's own state (OSQP's last
    # iterates and
    # adapted rho, qpOASES's working set) must not carry one run into the next.
    ctrl = design(arm3, op3, MPCSettings(formulation=formulation, backend=backend))
    dx0 = np.r_[np.radians([-8.0, 3.0, 2.0]), np.zeros(15)]
    runs = []
    for _ in range(2):
        ctrl.reset()
        runs.append(_linear_closed_loop(ctrl, dx0, 60)[0])
    assert np.any(np.abs(runs[0] - op3.u) > 1.0)  # the move is large enough to exercise the solver
    np.testing.assert_array_equal(runs[1], runs[0])


def test_mpc_with_kalman_estimator_on_encoders_and_strain_gauges(arm3, op3):
    from flexctrl.spec.controller_settings import SensorSettings

    ctrl = design(
        arm3,
        op3,
        MPCSettings(sensors=SensorSettings(outputs=("joints", "strain"), joints=1e-6, strain=1e-6)),
    )
    assert ctrl.measurement_names == ("q1", "q2", "q3", "kappa1", "kappa2", "kappa3")
    ctrl.reset()
    Ad, Bd = ctrl.plant.Ad, ctrl.plant.Bd
    dx = np.zeros(18)
    dx[:3] = np.radians([2.0, -2.0, 2.0])
    u = op3.u.copy()
    for k in range(300):
        y = ctrl.sensors.measure(op3.x + dx, u)
        u = ctrl.step(0.01 * k, y)
        dx = Ad @ dx + Bd @ (u - op3.u)
    assert np.max(np.abs(dx[:3])) < np.radians(0.05)
    assert ctrl.stats.fallbacks == []


@pytest.mark.parametrize("formulation", ["sparse", "condensed"])
def test_with_a_moving_reference_the_unconstrained_first_move_is_lqr_tracking(
    arm3, op3, formulation
):
    """Reference in the bounds only: the first move is LQR's u_ref - K (x - x_ref).

    The QP's pattern is unchanged.
    """
    from flexctrl.control.lqr import LQRSettings
    from flexctrl.control.reference_trajectory import ReferenceTrajectory
    from flexctrl.spec.reference import JointReference

    settings = MPCSettings(horizon=12, soft="deflection", formulation=formulation, osqp=TIGHT)
    ctrl = design(arm3, op3, settings)
    lqr = design(arm3, op3, LQRSettings(weights=settings.weights))
    path = JointReference(
        tuple(TARGET - np.radians([4.0, -2.0, 1.0])), tuple(TARGET), "quintic", move_time=1.0
    )
    ref = ReferenceTrajectory(arm3, path)
    pattern = ctrl.qp.A.copy()
    for c in (ctrl, lqr):
        c.set_reference(ref)
        c.reset()
    t = 0.4
    x_ref = ref.at(t, ctrl.sample_time)[0]
    dx = np.zeros(18)
    dx[:3] = np.radians([0.2, -0.1, 0.15])
    u_mpc, u_lqr = ctrl.step(t, x_ref + dx), lqr.step(t, x_ref + dx)
    u_ref = ref.at(t, ctrl.sample_time)[1]
    scale = np.max(np.abs(u_lqr - u_ref))
    assert np.max(np.abs(u_mpc - u_lqr)) < 1e-4 * scale
    assert (ctrl.qp.A != pattern).nnz == 0
    assert ctrl.stats.fallbacks == []
