"""Minimum-time arrival of the linear MPC: the earliest stage the arm can be held inside a band.

A quadratic tracking cost does not ask for speed: on a fast step a quadratic MPC overshoots
and creeps back into a tight band, whatever its weights, because ``sum z'Qz`` trades a late
small error against an early large one.  Minimum time is
a different question, and a linear programme answers it exactly on the prediction model:

    k* = min k  such that there are moves with  v_lo <= v <= v_hi          (torque limits)
                                       lo_d <= C_d z_j <= hi_d  for all j   (deflection limit)
                                      |C_a z_j| <= band         for j >= k  (arrival rows)

where ``z_j = Phi_j z_0 + Gamma_j T b`` is the condensed prediction (move blocking ``T``)
and ``C_a`` are the arrival rows of :func:`flexctrl.control.mpc.problem.arrival_rows` (the tip
position error and each joint's error as tip motion, m).  Feasibility is monotone in ``k``
(a plan that stays in the band from ``k`` on also does from ``k + 1``), so bisection over
the constrained stages needs ``log2(S)`` linear programmes (HiGHS through
:func:`scipy.optimize.linprog`), once per move.

The controller solves this when it first sees a target (its first sample after
:meth:`~flexctrl.control.controller.Controller.reset`) and fixes the absolute arrival time
``t_a = t_0 + (k* + 1) T_s + margin``.  From then on every QP keeps its quadratic cost but
asks the predicted states at and after ``t_a`` to be inside the band through the arrival
rows (soft, with the MPC's exact L1 slack penalty, so a plant that strays from the
prediction still gets a solution); the rows of earlier stages are released (unbounded).
The margin leaves the quadratic cost room to shape the motion and the feedback room to
correct the linear model's error; on the linear model alone ``margin = 0`` reaches the
band exactly at ``k*``.
"""

from __future__ import annotations

import numpy as np

from flexctrl.control.mpc.qp import QP


def _rows(qp: QP, lba: np.ndarray, uba: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(G (S, ns, nv), lower (S, ns), upper (S, ns))``: every soft row on the moves, bounded."""
    ns = qp.soft_rows.shape[1] // 2
    nv = qp.n_moves
    dense = qp.A.toarray()[:, :nv]
    upper_rows, lower_rows = qp.soft_rows[:, :ns], qp.soft_rows[:, ns:]
    return dense[upper_rows], lba[lower_rows], uba[upper_rows]


def shortest_arrival(
    qp: QP, z: np.ndarray, dv: np.ndarray | None = None, dc: np.ndarray | None = None
) -> int | None:
    """Index of the first constrained stage from which the band can be held, or None.

    Parameters
    ----------
    qp : QP
        A condensed QP with arrival rows (``qp.n_arrival > 0``).
    z : ndarray
        Scaled initial state deviation.
    dv, dc : ndarray, optional
        Reference shifts of the input and soft-row bounds (see :meth:`QP.vectors`).

    Returns
    -------
    int or None
        ``j`` such that the rows of the constrained stages ``j, j+1, ...`` can all hold,
        the smallest such; None when even the last stage alone cannot (horizon too short
        or limits too tight).
    """
    from scipy.optimize import linprog

    if not qp.n_arrival:
        raise ValueError("the QP has no arrival rows")
    _g, lba, uba, lbx, ubx = qp.vectors(z, dv, dc)
    G, lower, upper = _rows(qp, lba, uba)
    S, ns, nv = G.shape
    na = qp.n_arrival
    bounds = list(zip(lbx[:nv], ubx[:nv]))

    def feasible(first: int) -> bool:
        keep = np.ones((S, ns), bool)
        keep[:first, ns - na :] = False
        hi, lo = keep & np.isfinite(upper), keep & np.isfinite(lower)
        A_ub = np.vstack([G[hi], -G[lo]])
        b_ub = np.r_[upper[hi], -lower[lo]]
        res = linprog(np.zeros(nv), A_ub=A_ub, b_ub=b_ub, bounds=bounds, method="highs")
        return res.status == 0

    if not feasible(S - 1):
        return None
    lo, hi = -1, S - 1  # invariant: feasible(hi), not feasible(lo) (lo = -1: unknown below 0)
    if feasible(0):
        return 0
    lo = 0
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if feasible(mid):
            hi = mid
        else:
            lo = mid
    return hi


def stage_times(qp: QP, t: float, sample_time: float) -> np.ndarray:
    """Absolute time of the predicted state of every constrained stage of a QP solved at ``t``.

    Parameters
    ----------
    qp : QP
        The QP (its stages with soft rows).
    t : float
        When it is solved, s.
    sample_time : float
        s.

    Returns
    -------
    ndarray
        One time per constrained stage, s.
    """
    N = qp.moves.shape[0]
    steps = np.arange(N) if qp.soft_steps is None else qp.soft_steps
    return t + (steps + 1) * sample_time


__all__ = ["shortest_arrival", "stage_times"]
