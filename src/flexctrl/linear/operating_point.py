"""Operating points: a given state and input, or the static equilibrium at given joint angles.

:func:`equilibrium` holds the arm against gravity with the joints at given angles: the
elastic coordinates take their static deflection (``g(q) + K q = B tau``: Newton on the
elastic rows, the torques from the joint rows).  :func:`operating_point` wraps any given
state and input.  SI units; angles in radians.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike

from flexctrl.dynamics.model import Model
from flexctrl.errors import SolverError, SpecError, keyword_checked, keywords_checked
from flexctrl.linear.model_facts import state_names, stiffness_matrix
from flexctrl.spec.units import warn_if_degrees


@keywords_checked
@dataclass(frozen=True, eq=False)
class OperatingPoint:
    """A state and input about which a model is linearised.

    Attributes
    ----------
    x : ndarray (2N,)
        State ``(q, qd)`` (rad, m, rad/s, m/s).
    u : ndarray (n,)
        Joint torques, N m.
    kind : {"equilibrium", "given"}
        How it was made.
    residual : float
        ``max |f(x, u)|`` (0 for an exact equilibrium).
    iterations : int
        Newton iterations used (0 for a given point).
    """

    x: np.ndarray
    u: np.ndarray
    kind: Literal["equilibrium", "given"] = "given"
    residual: float = float("nan")
    iterations: int = 0

    def __post_init__(self) -> None:
        for name in ("x", "u"):
            value = np.array(getattr(self, name), dtype=float).ravel()
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n_q(self) -> int:
        """Number of coordinates N."""
        return self.x.size // 2

    @property
    def q(self) -> np.ndarray:
        """Coordinates (rad, m)."""
        return self.x[: self.n_q]

    @property
    def qd(self) -> np.ndarray:
        """Rates (rad/s, m/s)."""
        return self.x[self.n_q :]

    @property
    def joints(self) -> np.ndarray:
        """Joint angles (rad)."""
        return self.q[: self.u.size]


def _xdot(model: Model, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    return np.array(model.functions["f"](x, u), dtype=float).ravel()


def operating_point(model: Model, x: ArrayLike, u: ArrayLike) -> OperatingPoint:
    """Wrap a given state and input of ``model`` as an :class:`OperatingPoint`.

    Parameters
    ----------
    model : Model
        Gives the sizes and ``f`` (for the residual).
    x : array_like
        State ``(q, qd)``, ``2 N`` entries (rad, m, rad/s, m/s).
    u : array_like
        Joint torques, ``n`` entries (N m).

    Returns
    -------
    OperatingPoint
        ``kind="given"``, with the residual ``max |f(x, u)|``.
    """
    state = np.asarray(x, dtype=float).ravel()
    torques = np.asarray(u, dtype=float).ravel()
    if state.size != model.n_x:
        names = ", ".join(state_names(model))
        raise SpecError(
            f"state has {state.size} entries; expected {model.n_x} (q then qd: {names})", key="x"
        )
    if torques.size != model.n_u:
        raise SpecError(
            f"input has {torques.size} entries; expected {model.n_u} joint torques", key="u"
        )
    residual = float(np.max(np.abs(_xdot(model, state, torques)), initial=0.0))
    return OperatingPoint(state, torques, "given", residual, 0)


def _static_functions(model: Model) -> ca.Function:
    """``(qr, qf) -> (r_f, J_f, tau)``: elastic residual, its Jacobian in qf, joint torques."""
    n, N = model.n_u, model.n_q
    qr = ca.SX.sym("qr", n)
    qf = ca.SX.sym("qf", N - n)
    q = ca.vertcat(qr, qf)
    g = model.functions["g"](q)
    K = stiffness_matrix(model, q)
    static = g + ca.mtimes(K, q)  # = B tau at rest
    r_f = static[n:]
    return ca.Function(
        "static", [qr, qf], [r_f, ca.jacobian(r_f, qf), static[:n]], ["qr", "qf"], ["r", "J", "tau"]
    )


@keyword_checked
def equilibrium(
    model: Model,
    q_joints: Sequence[float] | np.ndarray,
    *,
    tol: float = 1e-12,
    max_iter: int = 50,
    q_flex0: Sequence[float] | np.ndarray | None = None,
) -> OperatingPoint:
    """The static equilibrium with the joints at ``q_joints`` (rad), held by joint torques.

    Solves ``[g(q) + K q]_f = 0`` for the elastic coordinates by Newton's method
    (Jacobian by CasADi AD, converged when the step is below ``tol`` relative to
    ``1 + |q_f|``) and takes the joint torques from the joint rows,
    ``tau = [g(q) + K q]_r``.  Velocities are zero.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The model to hold.
    q_joints : sequence of float
        Joint angles, rad (one per joint).
    tol : float
        Newton's relative step tolerance.
    max_iter : int
        Newton iterations at most.
    q_flex0 : sequence of float, optional
        Start for the elastic coordinates (m); default zero.

    Returns
    -------
    OperatingPoint
        ``x = (q, 0)`` and the holding torques ``u`` (N m).

    Raises
    ------
    SolverError
        If Newton does not converge in ``max_iter`` iterations.
    """
    n, N = model.n_u, model.n_q
    qr = np.asarray(q_joints, dtype=float).ravel()
    if qr.size != n:
        raise SpecError(f"{qr.size} joint angles given; expected {n}", key="q_joints")
    warn_if_degrees(qr, key="q_joints")
    qf = np.zeros(N - n) if q_flex0 is None else np.asarray(q_flex0, dtype=float).ravel()
    fun = _static_functions(model)
    iterations = 0
    if N > n:
        qf, iterations = _newton_on_elastic(fun, qr, qf, tol, max_iter)
    tau = np.array(fun(qr, qf)[2], dtype=float).ravel()
    x = np.concatenate([qr, qf, np.zeros(N)])
    residual = float(np.max(np.abs(_xdot(model, x, tau))))
    return OperatingPoint(x, tau, "equilibrium", residual, iterations)


def _newton_on_elastic(
    fun: ca.Function, qr: np.ndarray, qf: np.ndarray, tol: float, max_iter: int
) -> tuple[np.ndarray, int]:
    """``(q_f, iterations)`` where the elastic rows of :func:`_static_functions` vanish."""
    step = np.zeros_like(qf)
    for iterations in range(1, max_iter + 1):
        r, J, _ = fun(qr, qf)
        step = np.linalg.solve(np.array(J, dtype=float), np.array(r, dtype=float).ravel())
        qf = qf - step
        if np.max(np.abs(step)) <= tol * (1.0 + np.max(np.abs(qf))):
            return qf, iterations
    raise SolverError(
        f"equilibrium at joints {qr.tolist()} rad: Newton on the elastic coordinates did not "
        f"converge in {max_iter} iterations (last step {np.max(np.abs(step)):.3g})"
    )


def holding_torque_excess(model: Model, op: OperatingPoint) -> str:
    """Why the holding torques of ``op`` exceed the joint torque limits, or ``""`` when they do not.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        Its ``spec.joints`` give the limits (N m); a model without joints has none.
    op : OperatingPoint
        A static equilibrium (:func:`equilibrium`): ``u`` holds it (N m).

    Returns
    -------
    str
        One line naming the joint angles (deg), the torques and the limits (N m), or ``""``.
    """
    joints = getattr(model.spec, "joints", ())
    limits = np.array([getattr(j, "torque_limit", np.inf) for j in joints], dtype=float)
    u = np.asarray(op.u, dtype=float).ravel()
    if limits.size != u.size or not np.any(np.abs(u) > limits):
        return ""
    over = ", ".join(
        f"joint {i + 1}: |{u[i]:.4g}| > {limits[i]:.4g}" for i in np.flatnonzero(np.abs(u) > limits)
    )
    q = [round(math.degrees(a), 3) for a in np.asarray(op.x, dtype=float)[: u.size]]
    return (
        f"the static equilibrium at q = {q} deg needs holding torques {np.round(u, 3).tolist()} "
        f"N m beyond the torque limits {limits.tolist()} N m ({over}): no controller can hold "
        "the arm there"
    )
