"""Newmark + Baumgarte DAE solver (flexctrl.dynamics.fem.newmark_dae) against independent
references."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from flexctrl.beam.elements import assemble_beam
from flexctrl.dynamics.fem.casadi_dae import casadi_problem
from flexctrl.dynamics.fem.newmark_dae import (
    ConstraintViolationError,
    DAEProblem,
    NewtonConvergenceError,
    simulate,
)

MASS, G, LEN = 1.3, 9.81, 0.8
TH0 = 1.0
Q0 = np.array([LEN * np.sin(TH0), -LEN * np.cos(TH0)])


def pendulum(tangents: bool = True) -> DAEProblem:
    """Point mass on a rigid massless rod, Cartesian q = (x, y), Phi = x^2 + y^2 - L^2."""
    extra = dict(
        force_q=lambda q, qd, t: np.zeros((2, 2)),
        force_qd=lambda q, qd, t: np.zeros((2, 2)),
        h_q=lambda q, qd, t: np.zeros((1, 2)),
        h_qd=lambda q, qd, t: -4.0 * qd[None, :],
    )
    return DAEProblem(
        n_q=2,
        n_c=1,
        mass=lambda q, t: MASS * np.eye(2),
        force=lambda q, qd, t: np.array([0.0, -MASS * G]),
        phi=lambda q, t: np.array([q @ q - LEN**2]),
        phi_q=lambda q, t: 2.0 * q[None, :],
        phi_t=lambda q, t: np.zeros(1),
        h=lambda q, qd, t: np.array([-2.0 * qd @ qd]),
        **(extra if tangents else {}),
    )


@pytest.fixture(scope="module")
def pendulum_reference():
    """Angle ODE theta'' = -(g/L) sin theta, solved to 1e-13."""
    return solve_ivp(
        lambda t, y: [y[1], -G / LEN * np.sin(y[0])],
        (0.0, 2.0),
        [TH0, 0.0],
        method="DOP853",
        rtol=1e-13,
        atol=1e-13,
        dense_output=True,
    ).sol


def pendulum_errors(res, sol):
    th, om = sol(res.t)
    pos = np.abs(res.q - np.c_[LEN * np.sin(th), -LEN * np.cos(th)]).max()
    tension = MASS * (
        G * np.cos(th) + LEN * om**2
    )  # rod force; Phi_q^T lam = 2 lam q => T = 2 lam L
    return pos, np.abs(2.0 * LEN * res.lam[:, 0] - tension).max()


def test_pendulum_second_order_and_multipliers(pendulum_reference):
    errs = []
    for dt in (0.02, 0.01, 0.005, 0.0025):
        res = simulate(pendulum(), Q0, [0.0, 0.0], 2.0, dt)
        errs.append(pendulum_errors(res, pendulum_reference))
    errs = np.array(errs)
    orders = np.log2(errs[:-1] / errs[1:])
    assert np.all((orders > 1.9) & (orders < 2.1)), orders  # both q and lam
    assert errs[-1, 0] < 1e-4 and errs[-1, 1] < 1e-3


def test_pendulum_violation_bounded_and_consistent_start(pendulum_reference):
    res = simulate(pendulum(), Q0, [0.0, 0.0], 2.0, 1e-3)
    assert res.phi_violation.max() < 5e-6  # m^2 (Phi = x^2 + y^2 - L^2)
    assert res.phidot_violation.max() < 2e-5
    # Eqs 55-56 at rest: qdd0 = tangential gravity, rod force = m g cos(theta0)
    a_t = -G * np.sin(TH0)
    np.testing.assert_allclose(res.qdd[0], a_t * np.array([np.cos(TH0), np.sin(TH0)]), atol=1e-12)
    assert 2 * LEN * res.lam[0, 0] == pytest.approx(MASS * G * np.cos(TH0), rel=1e-12)
    assert res.t[-1] == pytest.approx(2.0) and res.q.shape == (2001, 2) and res.wall_time > 0


def test_fd_jacobian_and_casadi_backend_agree_with_hand_tangents():
    ref = simulate(pendulum(), Q0, [0.0, 0.0], 1.0, 0.01)
    fd = simulate(pendulum(tangents=False), Q0, [0.0, 0.0], 1.0, 0.01)
    np.testing.assert_allclose(fd.q, ref.q, atol=1e-10)
    q, qd, t = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("t")
    prob = casadi_problem(
        q, qd, t, MASS * ca.SX.eye(2), ca.vertcat(0, -MASS * G), ca.dot(q, q) - LEN**2
    )
    res = simulate(prob, Q0, [0.0, 0.0], 1.0, 0.01)
    np.testing.assert_allclose(res.q, ref.q, atol=1e-12)
    np.testing.assert_allclose(res.lam, ref.lam, atol=1e-10)


def test_casadi_time_dependent_constraint_derives_h():
    """Bead on a rod moving as y = x tan(w t): h from AD must match the hand derivation via the
    motion."""
    q, qd, t = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("t")
    w = 0.7
    prob = casadi_problem(
        q, qd, t, ca.SX.eye(2), ca.vertcat(0, -1.0), q[1] * ca.cos(w * t) - q[0] * ca.sin(w * t)
    )
    res = simulate(
        prob, [1.0, 0.0], [0.0, w], 1.0, 1e-3, max_violation=1e-6
    )  # consistent Phidot = 0
    assert res.phi_violation.max() < 1e-7
    # independent: r'' - r w^2 = -sin(w t) along the rod (gravity g = 1 in -y), r(0) = 1, r'(0) = 0
    sol = solve_ivp(
        lambda s, y: [y[1], y[0] * w**2 - np.sin(w * s)],
        (0, 1),
        [1.0, 0.0],
        rtol=1e-12,
        atol=1e-12,
        dense_output=True,
    ).sol
    r = sol(res.t)[0]
    np.testing.assert_allclose(
        res.q, np.c_[r * np.cos(w * res.t), r * np.sin(w * res.t)], atol=5e-7
    )


def oscillator(k: float = 4.0, m: float = 1.0) -> DAEProblem:
    K = np.array([[k]])
    return DAEProblem(
        n_q=1,
        n_c=0,
        mass=lambda q, t: np.array([[m]]),
        force=lambda q, qd, t: -K @ q,
        phi=lambda q, t: np.zeros(0),
        phi_q=lambda q, t: np.zeros((0, 1)),
        phi_t=lambda q, t: np.zeros(0),
        h=lambda q, qd, t: np.zeros(0),
        force_q=lambda q, qd, t: -K,
        force_qd=lambda q, qd, t: np.zeros((1, 1)),
        h_q=lambda q, qd, t: np.zeros((0, 1)),
        h_qd=lambda q, qd, t: np.zeros((0, 1)),
        linear=True,
    )


def test_unconstrained_oscillator_second_order():
    errs = []
    for dt in (0.1, 0.05, 0.025, 0.0125):
        res = simulate(oscillator(), [1.0], [0.0], 3.0, dt)
        errs.append(np.abs(res.q[:, 0] - np.cos(2.0 * res.t)).max())
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all((orders > 1.95) & (orders < 2.05)), orders


def locked_cantilever(n: int = 6) -> tuple[DAEProblem, np.ndarray, np.ndarray]:
    """Free-free beam whose root is locked by the constraints w0 = theta0 = 0."""
    b = assemble_beam(n, 1.0, 1.0, 1.0)
    A = np.zeros((2, b.M.shape[0]))
    A[0, 0] = A[1, 1] = 1.0
    z = np.zeros((b.M.shape[0],) * 2)
    prob = DAEProblem(
        n_q=b.M.shape[0],
        n_c=2,
        mass=lambda q, t: b.M,
        force=lambda q, qd, t: -b.K @ q,
        phi=lambda q, t: A @ q,
        phi_q=lambda q, t: A,
        phi_t=lambda q, t: np.zeros(2),
        h=lambda q, qd, t: np.zeros(2),
        force_q=lambda q, qd, t: -b.K,
        force_qd=lambda q, qd, t: z,
        h_q=lambda q, qd, t: np.zeros_like(A),
        h_qd=lambda q, qd, t: np.zeros_like(A),
        linear=True,
    )
    x = b.node_x
    q0 = np.zeros(b.M.shape[0])
    q0[0::2], q0[1::2] = 0.01 * x**2 * (3 - x) / 2, 0.01 * (6 * x - 3 * x**2) / 2  # tip-load shape
    return prob, q0, b


def energy(res, b):
    return 0.5 * np.einsum("ki,ij,kj->k", res.qd, b.M, res.qd) + 0.5 * np.einsum(
        "ki,ij,kj->k", res.q, b.K, res.q
    )


def test_energy_conserved_by_trapezoidal_rule_and_dissipated_by_damped_newmark():
    prob, q0, b = locked_cantilever()
    res = simulate(prob, q0, np.zeros_like(q0), 5.0, 2e-3)
    E = energy(res, b)
    assert np.abs(E / E[0] - 1.0).max() < 1e-10
    assert res.phi_violation.max() < 1e-14  # linear invariant constraints stay exact
    damped = simulate(prob, q0, np.zeros_like(q0), 5.0, 2e-3, alpha=0.3025, delta=0.6)
    Ed = energy(damped, b)
    assert Ed[-1] < 0.999 * Ed[0] and np.all(np.diff(Ed) < 1e-15 * Ed[0])


def test_printed_eq54_sign_diverges_and_eq49_sign_damps():
    q_bad = Q0 * 1.001  # initial position violation of 2e-3 L^2
    res = simulate(pendulum(), q_bad, [0.0, 0.0], 5.0, 1e-3)
    assert res.phi_violation[-1] < 0.01 * res.phi_violation[0]
    with pytest.raises(
        ConstraintViolationError, match=r"t = .* s, dt = 0.01 s, gamma = 5, beta = 5.*eq54"
    ):
        simulate(pendulum(), q_bad, [0.0, 0.0], 5.0, 0.01, baumgarte_form="eq54_printed")


def test_absurd_baumgarte_gains_at_large_step_raise():
    q_bad = Q0 * 1.001
    with pytest.raises(ConstraintViolationError, match=r"gamma = 1000, beta = 1000.*max\|Phi\|"):
        simulate(pendulum(), q_bad, [0.0, 0.0], 1.0, 0.01, gamma=1e3, beta=1e3)
    # the implicit variant of the same feedback is stable
    res = simulate(
        pendulum(), q_bad, [0.0, 0.0], 1.0, 0.01, gamma=1e3, beta=1e3, feedback="implicit"
    )
    assert res.phi_violation[-1] < 1e-5


def test_newton_failure_names_step_and_time():
    with pytest.raises(NewtonConvergenceError, match=r"step 1 \(t = 0.01 s"):
        simulate(pendulum(), Q0, [0.0, 0.0], 1.0, 0.01, max_iterations=1)
    with pytest.raises(ValueError):
        simulate(pendulum(tangents=False), Q0, [0.0, 0.0], 1.0, 0.01, jacobian="tangent")
