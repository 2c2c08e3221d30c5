"""A :class:`~flexctrl.dynamics.fem.newmark_dae.DAEProblem` from CasADi expressions.

The model supplies ``M(q, t)``, ``f(q, qd, t)`` and ``Phi(q, t)``; ``Phi_q``, ``Phi_t``, ``h``
(Eq 47) and every Newton tangent follow by automatic differentiation.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import casadi as ca
import numpy as np

from flexctrl.dynamics.fem.newmark_dae import Array, DAEProblem


def casadi_problem(
    q: Any, qd: Any, t: Any, mass: Any, force: Any, phi: Any, *, linear: bool = False
) -> DAEProblem:
    """Build a :class:`DAEProblem` from CasADi symbols and expressions.

    Parameters
    ----------
    q, qd, t
        CasADi ``SX``/``MX`` symbols (n x 1, n x 1, scalar).
    mass, force, phi
        Expressions for ``M(q,t)`` (n x n), ``f(q,qd,t)`` (n x 1), ``Phi(q,t)`` (m x 1, m
        may be 0).  ``Phi_q``, ``Phi_t``, ``h`` and all Newton tangents are derived by
        automatic differentiation, so the model supplies only M, f and Phi.
    """
    n = int(q.numel())
    m = int(phi.numel())
    phi = ca.reshape(phi, m, 1)
    phi_q = ca.jacobian(phi, q)
    phi_t = ca.jacobian(phi, t)
    phidot = ca.mtimes(phi_q, qd) + phi_t
    h = -(ca.mtimes(ca.jacobian(phidot, q), qd) + ca.jacobian(phidot, t))
    funcs = {
        "mass": ca.Function("M", [q, t], [mass]),
        "phi": ca.Function("Phi", [q, t], [phi]),
        "phi_q": ca.Function("Phi_q", [q, t], [phi_q]),
        "phi_t": ca.Function("Phi_t", [q, t], [phi_t]),
        "force": ca.Function("f", [q, qd, t], [force]),
        "force_q": ca.Function("f_q", [q, qd, t], [ca.jacobian(force, q)]),
        "force_qd": ca.Function("f_qd", [q, qd, t], [ca.jacobian(force, qd)]),
        "h": ca.Function("h", [q, qd, t], [h]),
        "h_q": ca.Function("h_q", [q, qd, t], [ca.jacobian(h, q)]),
        "h_qd": ca.Function("h_qd", [q, qd, t], [ca.jacobian(h, qd)]),
    }
    shapes = {
        "mass": (n, n),
        "phi": (m,),
        "phi_q": (m, n),
        "phi_t": (m,),
        "force": (n,),
        "force_q": (n, n),
        "force_qd": (n, n),
        "h": (m,),
        "h_q": (m, n),
        "h_qd": (m, n),
    }

    def wrap(name: str) -> Callable[..., Array]:
        fun, shape = funcs[name], shapes[name]
        return lambda *args: np.asarray(fun(*args).full(), dtype=float).reshape(shape)

    return DAEProblem(n_q=n, n_c=m, linear=linear, **{k: wrap(k) for k in funcs})
