"""The Jacobian of the forward dynamics through one factorisation of the mass matrix, for the NMPC.

The model's ``f(x, u) = (qd, qdd)`` with ``M(q) qdd = r(q, qd, u)``, where
``r = B u - c(q, qd) - g(q) - K q - D qd`` (the generalised forces of
:mod:`flexctrl.dynamics.model`).  Differentiating ``f`` symbolically differentiates
the solve with ``M``: on the three-link arm with two modes per link the Jacobian
takes ten times the instructions of ``f`` itself.  Differentiating
``M(q) qdd(x) = r(x)`` instead gives::

    d qdd / dx = M^-1 (dr/dx - d(M a)/dq |_{a = qdd} [I 0]),    d qdd / du = M^-1 dr/du

with ``a`` held fixed while ``M a`` is differentiated: one LDL^T factorisation of
``M`` (:func:`flexctrl.dynamics.dense_ldl.ldl_solve`, merged over all right-hand sides by
common subexpression elimination) serves ``qdd`` and every column of the Jacobian.

:func:`factored_dynamics` returns ``f`` and ``(f, f_x, f_u)`` built this way with the
numeric constants of the pieces as an input (:func:`flexctrl.dynamics.parametric.constants_as_parameters`),
so the compiled NMPC sensitivities still depend only on the model's graph structure.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from flexctrl.dynamics.dense_ldl import ldl_solve
from flexctrl.dynamics.parametric import constants_as_parameters


def equation_terms(model) -> ca.Function:
    """``terms(x, u, a) -> (M, r, r_x - [d(M a)/dq, 0], r_u)`` of ``M(q) qdd = r(x, u)`` (SX).

    ``a`` stands for ``qdd`` held fixed; the third output is ``dr/dx`` minus the
    derivative of ``M(q) a`` with respect to ``q`` (zero columns for ``qd``).
    """
    fn = model.functions
    N, n = model.n_q, model.n_u
    q, qd, u, a = ca.SX.sym("q", N), ca.SX.sym("qd", N), ca.SX.sym("u", n), ca.SX.sym("a", N)
    K = ca.SX(fn["K"](q) if fn["K"].n_in() > 0 else fn["K"]()["K"])
    D = ca.SX(fn["D"](q) if fn["D"].n_in() > 0 else fn["D"]()["D"])
    M = ca.SX(fn["M"](q))
    B = ca.vertcat(ca.SX.eye(n), ca.SX.zeros(N - n, n))
    r = ca.mtimes(B, u) - fn["c"](q, qd) - fn["g"](q) - ca.mtimes(K, q) - ca.mtimes(D, qd)
    x = ca.vertcat(q, qd)
    r_x = ca.jacobian(
        r - ca.mtimes(M, a), x
    )  # one Jacobian: M a and c share their configuration derivatives
    return ca.Function(
        "nmpc_terms",
        [x, u, a],
        [M, r, r_x, ca.jacobian(r, u)],
        ["x", "u", "a"],
        ["M", "r", "r_x", "r_u"],
        {"cse": True},
    )


def factored_dynamics(model) -> tuple[ca.Function, ca.Function, np.ndarray]:
    """``f(x, u, c)`` and ``f_jac(x, u, c) -> (f, f_x, f_u)`` from one LDL^T of ``M`` per call.

    Parameters
    ----------
    model : Model
        Any model with ``M``, ``c``, ``g``, ``K``, ``D`` and ``f``; the rebuilt ``f`` is
        checked against the model's at a random state (``ValueError`` if it differs).

    Returns
    -------
    f, f_jac : casadi.Function
        SX Functions of ``(x, u, c)`` (``(x, u)`` when the constants could not be lifted).
    c : ndarray
        The constants to pass as the last input (empty when not lifted).
    """
    terms, const = constants_as_parameters(equation_terms(model))
    N, n = model.n_q, model.n_u
    x, u = ca.SX.sym("x", 2 * N), ca.SX.sym("u", n)
    cs = [ca.SX.sym("c", const.size)] if const.size else []
    M, r, _, _ = terms(x, u, ca.SX.zeros(N), *cs)
    qdd = ldl_solve(M, r)
    _, _, r_x, r_u = terms(x, u, qdd, *cs)
    solve_columns = lambda R: ca.horzcat(*[ldl_solve(M, R[:, j]) for j in range(R.shape[1])])  # noqa: E731
    xdot = ca.vertcat(x[N:], qdd)
    f_x = ca.vertcat(ca.horzcat(ca.SX(N, N), ca.SX.eye(N)), solve_columns(r_x))
    f_u = ca.vertcat(ca.SX(N, n), solve_columns(r_u))
    names = ["x", "u"] + (["c"] if cs else [])
    f = ca.Function("f_factored", [x, u, *cs], [xdot], names, ["xdot"], {"cse": True})
    f_jac = ca.Function(
        "f_jac_factored",
        [x, u, *cs],
        [xdot, f_x, f_u],
        names,
        ["xdot", "f_x", "f_u"],
        {"cse": True},
    )
    rng = np.random.default_rng(0)
    x0, u0 = 0.1 * rng.standard_normal(2 * N), rng.standard_normal(n)
    want = np.array(model.functions["f"](x0, u0), dtype=float).ravel()
    got = np.array(f(x0, u0, *([const] if cs else [])), dtype=float).ravel()
    if not np.allclose(got, want, rtol=1e-9, atol=1e-9 * max(1.0, float(np.max(np.abs(want))))):
        raise ValueError(
            f"model {model.name!r}: M(q)^-1 (B u - c - g - K q - D qd) does not reproduce its f "
            f'(max difference {np.max(np.abs(got - want)):.3g}); use jacobian = "symbolic"'
        )
    return f, f_jac, const


__all__ = ["equation_terms", "factored_dynamics"]
