"""Lagrange's equations of the assumed-modes arm and the model's named Functions.

From the kinematics and energies of :func:`flexctrl.dynamics.amm_kinematics.arm_expressions`:
``M qdd + c + g + K q + D qd = B tau`` with ``c = (d(M qd)/dq) qd - dT/dq`` (or the bodies'
convective form), ``g = dU_g/dq``, ``B = [I_n; 0]``, solved for ``qdd`` symbolically
(:func:`flexctrl.dynamics.dense_ldl.ldl_solve` or ``casadi.solve``).
"""

from __future__ import annotations

import casadi as ca

from flexctrl.dynamics.amm_kinematics import ArmExpressions
from flexctrl.dynamics.amm_modal import Expansion
from flexctrl.dynamics.dense_ldl import ldl_solve


def lagrange_equations(
    ex: ArmExpressions,
    K: ca.SX,
    D: ca.SX,
    E_el: ca.SX,
    symbols: tuple[ca.SX, ca.SX, ca.SX],
    solver: str,
    scheduled: bool,
) -> dict[str, ca.SX]:
    """Lagrange's equations, solved for ``qdd``, and the model's other outputs, by name.

    Parameters
    ----------
    ex : ArmExpressions
        Mass matrix, energies, hub positions and tip deflections of the arm.
    K, D : casadi.SX
        Modal stiffness (N/m per modal coordinate) and damping of the elastic coordinates.
    E_el : casadi.SX
        Elastic energy (J).
    symbols : tuple of casadi.SX
        ``(q, qd, u)``: coordinates (rad, m), rates, joint torques (N m).
    solver : {"ldl", "qr"}
        How ``M qdd = rhs`` is solved: the dense LDL of :mod:`.dense_ldl` or ``casadi.solve``
        (QR).
    scheduled : bool
        Modes scheduled on the configuration: the elastic force comes from the gradient of
        ``ex.elastic_energy`` rather than from ``K q`` alone.

    Returns
    -------
    dict of str to casadi.SX
        ``M``, ``c``, ``g``, ``K``, ``D``, ``xdot``, the energies (J), the tip position and
        velocity (m, m/s), the hub positions (m) and the tip deflections and slopes.
    """
    q, qd, u = symbols
    n, N = u.shape[0], q.shape[0]
    M = ex.mass_matrix
    Mqd = ca.mtimes(M, qd)
    E_kin = 0.5 * ca.dot(qd, Mqd)
    if ex.coriolis is not None:
        c = ex.coriolis
    else:
        c = ca.jtimes(Mqd, q, qd) - ca.gradient(E_kin, q)
    g = ca.gradient(ex.gravity_energy, q)
    if scheduled:
        g = g + ca.gradient(ex.elastic_energy, q) - ca.mtimes(K, q)
    B = ca.vertcat(ca.SX.eye(n), ca.SX.zeros(N - n, n))
    rhs = ca.mtimes(B, u) - c - g - ca.mtimes(K, q) - ca.mtimes(D, qd)
    qdd = ldl_solve(M, rhs) if solver == "ldl" else ca.solve(M, rhs)
    tip = ex.positions[:, n]
    return {
        "M": M,
        "c": c,
        "g": g,
        "K": K,
        "D": D,
        "xdot": ca.vertcat(qd, qdd),
        "E_kin": E_kin,
        "E_el": E_el,
        "E_grav": ex.gravity_energy,
        "tip": tip,
        "tip_v": ca.jtimes(tip, q, qd),
        "hubs": ex.positions,
        "w": ex.tip_deflection,
        "dw": ex.tip_slope,
    }


def model_functions(
    expr: dict[str, ca.SX],
    K: ca.SX,
    D: ca.SX,
    symbols: tuple[ca.SX, ca.SX, ca.SX],
    scheduled: bool,
    expansion: Expansion | None,
) -> dict[str, ca.Function]:
    """The model's named Functions (:mod:`flexctrl.dynamics.model`) of the expressions.

    Parameters
    ----------
    expr : dict of str to casadi.SX
        The expressions of :func:`lagrange_equations`.
    K, D : casadi.SX
        Modal stiffness and damping, constant Functions when the modes are frozen.
    symbols : tuple of casadi.SX
        ``(q, qd, u)``.
    scheduled : bool
        Modes scheduled on the configuration (``K`` and ``D`` depend on ``q``).
    expansion : tuple of lists of casadi.SX, optional
        Symbols and the values substituted for them in every expression (the scheduled
        tables' expansion point).

    Returns
    -------
    dict of str to casadi.Function
        ``M``, ``c``, ``g``, ``K``, ``D``, ``f``, ``energies``, ``tip``, ``hubs``,
        ``deflection``.
    """
    q, qd, u = symbols
    if expansion is not None:  # the tables' expansion point is the current configuration
        expr = dict(zip(expr, ca.substitute(list(expr.values()), *expansion)))
    x = ca.vertcat(q, qd)
    opts = {"cse": True}
    return {
        "M": ca.Function("M", [q], [expr["M"]], ["q"], ["M"], opts),
        "c": ca.Function("c", [q, qd], [expr["c"]], ["q", "qd"], ["c"], opts),
        "g": ca.Function("g", [q], [expr["g"]], ["q"], ["g"], opts),
        "K": ca.Function("K", [q], [expr["K"]], ["q"], ["K"], opts)
        if scheduled
        else ca.Function("K", [], [K], [], ["K"]),
        "D": ca.Function("D", [q], [expr["D"]], ["q"], ["D"], opts)
        if scheduled
        else ca.Function("D", [], [D], [], ["D"]),
        "f": ca.Function("f", [x, u], [expr["xdot"]], ["x", "u"], ["xdot"], opts),
        "energies": ca.Function(
            "energies",
            [q, qd],
            [expr["E_kin"], expr["E_el"], expr["E_grav"]],
            ["q", "qd"],
            ["E_kin", "E_el", "E_grav"],
            opts,
        ),
        "tip": ca.Function(
            "tip", [q, qd], [expr["tip"], expr["tip_v"]], ["q", "qd"], ["p", "v"], opts
        ),
        "hubs": ca.Function("hubs", [q], [expr["hubs"]], ["q"], ["p"], opts),
        "deflection": ca.Function(
            "deflection", [q], [expr["w"], expr["dw"]], ["q"], ["w", "dw"], opts
        ),
    }
