"""The rigid R-P arm written out by hand, the reference of the rigid-limit tests of the full-coupling models."""

from __future__ import annotations

import math

from scipy.integrate import solve_ivp


def rigid_rp(spec, forces, t_eval):
    """Rigid R-P arm, written out by hand: T = 1/2 J(r_E) theta'^2 + 1/2 m W'^2, V from gravity."""
    L, rho, mt, mc, Jh = spec.length, spec.mass_per_length, spec.payload_mass, spec.carriage_mass, spec.hub_inertia
    gx, gy = spec.gravity
    mtot = mc + rho * L + mt

    def rhs(t, y):
        th, W, thd, Wd = y
        rE = spec.support_outer - L + W
        J = Jh + mc * rE**2 + rho * (L * rE**2 + L**2 * rE + L**3 / 3) + mt * (rE + L) ** 2
        dJ = 2 * mc * rE + rho * (2 * L * rE + L**2) + 2 * mt * (rE + L)
        first = mc * rE + rho * (L * rE + L * L / 2) + mt * (rE + L)
        g_ax, g_perp = gx * math.cos(th) + gy * math.sin(th), -gx * math.sin(th) + gy * math.cos(th)
        return [thd, Wd, (forces.torque(t) + g_perp * first - dJ * Wd * thd) / J,
                (forces.force(t) + mtot * g_ax + 0.5 * dJ * thd**2) / mtot]

    sol = solve_ivp(rhs, (t_eval[0], t_eval[-1]), [forces.theta0, forces.W0, 0.0, 0.0], t_eval=t_eval,
                    method="DOP853", rtol=1e-11, atol=1e-12)
    return sol.y[0], sol.y[1]
