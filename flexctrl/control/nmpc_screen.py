"""The RTI's QP screened for its soft rows: solve without them first, keep that when they hold.

The RTI's QP (:mod:`flexctrl.control.nmpc`) carries soft output constraints, two rows and
one slack per limited output and stage, penalised by ``l1 s + l2 s^2 / 2`` with
``l1 > 0``.  Drop the soft rows and the slacks and solve what is left (the shooting
equalities, the torque bounds, the same costs).  If its solution ``w`` satisfies every
soft row with no slack (``c_lo <= C z_{k+1} <= c_hi`` on all stages), then ``(w, s = 0)``
solves the whole QP: it is feasible, and the KKT conditions of the smaller problem with
zero multipliers on the soft rows and the multiplier ``l1 >= 0`` on every active bound
``s >= 0`` are those of the whole problem (convex, so that is its optimum).  Otherwise the
whole QP is solved as before.  Both answers are the same optimum to the interior point's
tolerance, not to the bit (two solves take different iterates), so the closed-loop
numbers move in their last digits (``docs/control.md``, "NMPC speed").

The smaller QP has ``m`` instead of ``m + ns`` inputs and no general rows per stage: on the
benchmark's problem (12 states, 3 torques, 3 deflection limits, horizon 20; ``flexctrl bench
mpc``, in blocks) the QP step takes 0.57 instead of 0.76 ms, 3 iterations instead of 4.
Samples whose prediction reaches a deflection limit pay both solves.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from flexctrl.sim.bound import BoundFunction


def hpipm_options(N: int, n: int, nu: int, ng: int, warm_start: bool) -> dict:
    """``casadi.conic`` options of HPIPM for ``N`` stages of ``n`` states, ``nu`` inputs and ``ng`` rows each."""
    return {"N": N, "nx": [n] * (N + 1), "nu": [nu] * N + [0], "ng": [ng] * N + [0],
            "hpipm": {"mode": "speed", "iter_max": 30, "res_g_max": 1e-5, "res_b_max": 1e-6,
                      "res_d_max": 1e-6, "res_m_max": 1e-6, **({"warm_start": 1} if warm_start else {})}}


class ScreenedQP:
    """The RTI's QP without its soft rows and slacks (see the module docstring); one per controller.

    Parameters
    ----------
    layout : nmpc._Layout
        Index bookkeeping of the whole QP's ``w = [z_0, v_0, s_0, ..., z_N]``.
    H : ndarray
        The whole QP's Hessian (dense, ``nw x nw``).
    a_sparsity : casadi.Sparsity
        Sparsity of the whole QP's constraint matrix (per stage: ``n`` shooting rows, then
        ``2 ns`` soft rows).
    C, c_lo, c_hi : ndarray
        The soft rows' outputs ``C z_{k+1}`` and their limits.
    warm_start : bool
        HPIPM starts from the shifted previous solution.
    """

    def __init__(self, layout, H: np.ndarray, a_sparsity: ca.Sparsity, C: np.ndarray, c_lo: np.ndarray,
                 c_hi: np.ndarray, warm_start: bool):
        n, m, ns, N = layout.n, layout.m, layout.ns, layout.N
        self.layout = layout
        slack = np.zeros(layout.nw, dtype=bool)
        slack[layout.s.ravel()] = True
        #: the whole QP's variables and shooting rows the smaller one keeps
        self.keep = np.flatnonzero(~slack)
        self.rows = np.concatenate([k * (n + 2 * ns) + np.arange(n) for k in range(N)])
        # nonzeros of the whole A that the kept rows and columns select, in the smaller A's order
        numbered = ca.DM(a_sparsity, np.arange(1, a_sparsity.nnz() + 1, dtype=float))
        sub = numbered[self.rows.tolist(), self.keep.tolist()]
        self.entries = np.array(sub.nonzeros(), dtype=int) - 1
        Hk = H[np.ix_(self.keep, self.keep)]
        H_sp = ca.DM(ca.sparsify(ca.DM(Hk)))
        self.qp = ca.conic("nmpc_qp_screened", "hpipm", {"h": H_sp.sparsity(), "a": sub.sparsity()},
                           {"error_on_fail": False, **hpipm_options(N, n, m, 0, warm_start)})
        self._bound = BoundFunction(self.qp, {"h": np.array(H_sp.nonzeros(), dtype=float)}, renew=True)
        self._in = self._bound.arrays
        self._x = self._bound.arrays["x"].reshape(-1)
        self.C, self.c_lo, self.c_hi = np.asarray(C, dtype=float), np.asarray(c_lo, dtype=float), np.asarray(c_hi, dtype=float)
        #: the smaller QP's ``z_1 .. z_N`` in its own ``w``
        self._z_next = np.array([self.keep.searchsorted(layout.z[k + 1]) for k in range(N)])

    def solve(self, a: np.ndarray, lba: np.ndarray, uba: np.ndarray, g: np.ndarray, lbx: np.ndarray,
              ubx: np.ndarray, w0: np.ndarray) -> tuple[np.ndarray | None, dict]:
        """The whole QP's solution with zero slacks if the smaller QP's satisfies the soft rows, else None; its stats.

        Arguments are the whole QP's data (``a`` the nonzeros of its constraint matrix).
        Raises as the QP solver does (CasADi's checks).
        """
        keep, rows = self.keep, self.rows
        self._in["a"][:] = a[self.entries]
        self._in["lba"][:] = lba[rows]
        self._in["uba"][:] = uba[rows]
        self._in["g"][:] = g[keep]
        self._in["lbx"][:] = lbx[keep]
        self._in["ubx"][:] = ubx[keep]
        self._in["x0"][:] = w0[keep]
        self._bound.evaluate()
        stats = self._bound.stats()
        x = self._x
        if not stats.get("success", False) or not np.all(np.isfinite(x)):
            return None, stats
        y = self.C @ x[self._z_next].T  # (ns, N): the limited outputs on z_1 .. z_N
        if np.any(y > self.c_hi[:, None]) or np.any(y < self.c_lo[:, None]):
            return None, stats
        w = np.zeros(self.layout.nw)
        w[keep] = x
        return w, stats


__all__ = ["ScreenedQP", "hpipm_options"]
