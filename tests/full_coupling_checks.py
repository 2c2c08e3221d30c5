"""Checks shared by the tests of the full-coupling models: the rigid R-P arm written out by hand
(the reference of the rigid limit) and the constraint derivatives against central differences."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.integrate import solve_ivp


def rigid_rp(spec, forces, t_eval):
    """Rigid R-P arm, written out by hand: T = 1/2 J(r_E) theta'^2 + 1/2 m W'^2, V from gravity."""
    L, rho, mt, mc, Jh = (
        spec.length,
        spec.mass_per_length,
        spec.payload_mass,
        spec.carriage_mass,
        spec.hub_inertia,
    )
    gx, gy = spec.gravity
    mtot = mc + rho * L + mt

    def rhs(t, y):
        th, W, thd, Wd = y
        rE = spec.support_outer - L + W
        J = Jh + mc * rE**2 + rho * (L * rE**2 + L**2 * rE + L**3 / 3) + mt * (rE + L) ** 2
        dJ = 2 * mc * rE + rho * (2 * L * rE + L**2) + 2 * mt * (rE + L)
        first = mc * rE + rho * (L * rE + L * L / 2) + mt * (rE + L)
        g_ax, g_perp = gx * math.cos(th) + gy * math.sin(th), -gx * math.sin(th) + gy * math.cos(th)
        return [
            thd,
            Wd,
            (forces.torque(t) + g_perp * first - dJ * Wd * thd) / J,
            (forces.force(t) + mtot * g_ax + 0.5 * dJ * thd**2) / mtot,
        ]

    sol = solve_ivp(
        rhs,
        (t_eval[0], t_eval[-1]),
        [forces.theta0, forces.W0, 0.0, 0.0],
        t_eval=t_eval,
        method="DOP853",
        rtol=1e-11,
        atol=1e-12,
    )
    return sol.y[0], sol.y[1]


def check_rigid_limit(spec, W0: float) -> None:
    """Prescribed torque and force (2 N m, 2 N sines over 1 s, gravity 1 m/s^2, payload 0.3 kg):
    with EI x 1e4 theta and W follow :func:`rigid_rp` to the Newmark error, which halving dt cuts
    by ~4; with the file's EI the flexible arm is measurably different (the check can fail)."""
    from flexctrl.dynamics.fem.rp_arm_full import RPForces, simulate_rp_arm_full

    spec = dataclasses.replace(spec, gravity=(0.0, -1.0), payload_mass=0.3)
    forces = RPForces.sine(2.0, 2.0, 1.0, theta0=0.3, W0=W0)
    errors = {}
    for scale, dt in ((1e4, 1e-3), (1e4, 5e-4), (1.0, 1e-3)):
        res = simulate_rp_arm_full(
            dataclasses.replace(spec, EI=spec.EI * scale), forces, 4, dt=dt, duration=1.0
        )
        th, W = rigid_rp(spec, forces, res.t)
        assert np.ptp(th) > 0.1 and np.ptp(W) > 0.05  # a real motion
        assert res.phi_violation.max() < 1e-6
        errors[scale, dt] = max(np.abs(res.theta - th).max(), np.abs(res.W - W).max())
    assert errors[1e4, 1e-3] < 1e-5  # rad and m, against 0.2 rad and 0.11 m of motion
    assert (
        errors[1e4, 1e-3] / errors[1e4, 5e-4] > 3.0
    )  # what remains is O(dt^2) time discretisation
    assert errors[1.0, 1e-3] > 30 * errors[1e4, 1e-3]  # flexibility shows at the file's EI


def check_constraint_derivatives(model, W: float, seed: int) -> None:
    """Phi_z, h (Eq 47), h_z and h_zd of the W-dependent rows against central differences at a
    random state with overhang ``W`` (m); ``M`` symmetric positive definite there."""
    prob = model.problem()
    rng = np.random.default_rng(seed)
    z = np.r_[1e-3 * rng.standard_normal(model.ne), 0.4, W]
    zd = np.r_[1e-2 * rng.standard_normal(model.ne), 0.8, 0.3]
    zdd = np.r_[rng.standard_normal(model.ne), 0.5, -0.7]
    eps = 1e-4

    def path(s):
        return z + s * zd + 0.5 * s * s * zdd

    second = (prob.phi(path(eps), 0) - 2 * prob.phi(path(0), 0) + prob.phi(path(-eps), 0)) / eps**2
    np.testing.assert_allclose(
        prob.phi_q(z, 0) @ zdd - prob.h(z, zd, 0), second, rtol=1e-5, atol=1e-6
    )
    for k in range(model.nz):
        e = np.zeros(model.nz)
        e[k] = 1e-6
        np.testing.assert_allclose(
            (prob.phi(z + e, 0) - prob.phi(z - e, 0)) / 2e-6,
            prob.phi_q(z, 0)[:, k],
            rtol=1e-6,
            atol=1e-8,
        )
        np.testing.assert_allclose(
            (prob.h(z + e, zd, 0) - prob.h(z - e, zd, 0)) / 2e-6,
            prob.h_q(z, zd, 0)[:, k],
            rtol=1e-5,
            atol=1e-6,
        )
        np.testing.assert_allclose(
            (prob.h(z, zd + e, 0) - prob.h(z, zd - e, 0)) / 2e-6,
            prob.h_qd(z, zd, 0)[:, k],
            rtol=1e-5,
            atol=1e-6,
        )
    M = prob.mass(z, 0)
    np.testing.assert_allclose(M, M.T, atol=1e-14)
    assert np.linalg.eigvalsh(M).min() > 0
