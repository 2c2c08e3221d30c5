"""The RTI's QP screened for its soft rows: solve without them first, keep that when they hold.

The RTI's QP (:mod:`flexctrl.control.nmpc.controller`) carries soft output constraints, two
rows and one slack per limited output and stage, penalized by ``l1 s + l2 s^2 / 2`` with
``l1 > 0``.  Drop the soft rows and the slacks and solve what is left (the shooting
equalities, the torque bounds, the same costs).  If its solution ``w`` satisfies every soft
row with no slack (``c_lo <= C z_{k+1} <= c_hi`` on all stages), then ``(w, s = 0)`` solves
the whole QP: it is feasible, and the KKT conditions of the smaller problem with zero
multipliers on the soft rows and the multiplier ``l1 >= 0`` on every active bound ``s >= 0``
are those of the whole problem (convex, so that is its optimum).  Otherwise the whole QP is
solved.  Both answers are the same optimum to the interior point's tolerance, not to the bit
(two solves take different iterates).

Why: the smaller QP has ``m`` instead of ``m + ns`` inputs and no general rows per stage, so
it takes fewer and cheaper iterations; only samples whose prediction reaches a limit pay
both solves.  Since it has only the torque bounds, it is solved by HPIPM called directly
(:class:`HpipmStages`, :mod:`flexctrl.control.nmpc.hpipm_ocp`: memory made once, ``z_0``
eliminated, no state boxes).  When CasADi's ``libhpipm`` cannot be loaded, the smaller QP
falls back to HPIPM through ``casadi.conic`` and :attr:`ScreenedQP.backend` says so.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from flexctrl.control.nmpc.hpipm_ocp import HpipmOCP, HpipmUnavailable
from flexctrl.sim.bound import BoundFunction


def hpipm_options(N: int, n: int, nu: int, ng: int, warm_start: bool) -> dict:
    """``casadi.conic`` options of HPIPM for ``N`` stages.

    Parameters
    ----------
    N : int
        Stages.
    n, nu, ng : int
        States, inputs and general rows per stage.
    warm_start : bool
        Start from the primal guess given.

    Returns
    -------
    dict
    """
    return {
        "N": N,
        "nx": [n] * (N + 1),
        "nu": [nu] * N + [0],
        "ng": [ng] * N + [0],
        "hpipm": {
            "mode": "speed",
            "iter_max": 30,
            "res_g_max": 1e-5,
            "res_b_max": 1e-6,
            "res_d_max": 1e-6,
            "res_m_max": 1e-6,
            **({"warm_start": 1} if warm_start else {}),
        },
    }


class ScreenedQP:
    """The RTI's QP without its soft rows and slacks (module docstring); one per controller.

    Parameters
    ----------
    layout : flexctrl.control.nmpc.casadi_functions.Layout
        Index bookkeeping of the whole QP's ``w = [z_0, v_0, s_0, ..., z_N]``.
    H : ndarray
        The whole QP's Hessian (dense, ``nw x nw``).
    a_sparsity : casadi.Sparsity
        Sparsity of the whole QP's constraint matrix (per stage: ``n`` shooting rows, then
        ``2 ns`` soft rows).
    C, c_lo, c_hi : ndarray
        The soft rows' outputs ``C z_{k+1}`` and their limits (scaled).
    warm_start : bool
        HPIPM starts from the shifted previous solution.

    Attributes
    ----------
    backend : str
        How the smaller QP is solved: ``"hpipm (direct)"``, or ``"casadi.conic hpipm (why)"``
        when HPIPM's library cannot be called directly.
    """

    def __init__(
        self,
        layout,
        H: np.ndarray,
        a_sparsity: ca.Sparsity,
        C: np.ndarray,
        c_lo: np.ndarray,
        c_hi: np.ndarray,
        warm_start: bool,
    ):
        n, ns, N = layout.n, layout.ns, layout.N
        self.layout = layout
        slack = np.zeros(layout.nw, dtype=bool)
        slack[layout.s.ravel()] = True
        #: the whole QP's variables and shooting rows the smaller one keeps
        self.keep = np.flatnonzero(~slack)
        self.rows = np.concatenate([k * (n + 2 * ns) + np.arange(n) for k in range(N)])
        # the whole A's sparsity holding its nonzeros' numbers (1-based), to select the kept ones
        numbered = ca.DM(a_sparsity, np.arange(1, a_sparsity.nnz() + 1, dtype=float))
        self.C, self.c_lo, self.c_hi = (np.asarray(v, dtype=float) for v in (C, c_lo, c_hi))
        #: the smaller QP's ``z_1 .. z_N`` in its own ``w``
        self._z_next = np.array([self.keep.searchsorted(layout.z[k + 1]) for k in range(N)])
        options = hpipm_options(N, n, layout.m, 0, warm_start)
        self.direct: HpipmStages | None = None
        try:
            self.direct = HpipmStages(layout, H, numbered, self.rows, options["hpipm"])
            self.backend = "hpipm (direct)"
        except HpipmUnavailable as exc:
            self.backend = f"casadi.conic hpipm ({exc})"
            self._through_conic(H, numbered, options)

    def _through_conic(self, H: np.ndarray, numbered: ca.DM, options: dict) -> None:
        """The fall-back: the smaller QP through ``casadi.conic``'s HPIPM, on bound buffers."""
        sub = numbered[self.rows.tolist(), self.keep.tolist()]
        self.entries = np.array(sub.nonzeros(), dtype=int) - 1
        H_sp = ca.DM(ca.sparsify(ca.DM(H[np.ix_(self.keep, self.keep)])))
        self.qp = ca.conic(
            "nmpc_qp_screened",
            "hpipm",
            {"h": H_sp.sparsity(), "a": sub.sparsity()},
            {"error_on_fail": False, **options},
        )
        self._bound = BoundFunction(
            self.qp, {"h": np.array(H_sp.nonzeros(), dtype=float)}, renew=True
        )
        self._in = self._bound.arrays
        self._x = self._bound.arrays["x"].reshape(-1)

    def solve(
        self,
        a: np.ndarray,
        lba: np.ndarray,
        uba: np.ndarray,
        g: np.ndarray,
        lbx: np.ndarray,
        ubx: np.ndarray,
        w0: np.ndarray,
    ) -> tuple[np.ndarray | None, dict]:
        """The whole QP's solution with zero slacks, if the smaller QP's holds the soft rows.

        Raises as the QP solver does (CasADi's checks).

        Parameters
        ----------
        a : ndarray
            The nonzeros of the whole QP's constraint matrix.
        lba, uba : ndarray
            The whole QP's row bounds.
        g : ndarray
            The whole QP's linear cost.
        lbx, ubx : ndarray
            The whole QP's variable bounds.
        w0 : ndarray
            The start (the whole QP's variables).

        Returns
        -------
        tuple
            ``(w or None, stats)``: None when the smaller QP failed or a soft row does not hold.
        """
        if self.direct is not None:
            w, stats = self.direct.solve(a, lba, g, lbx, ubx, w0)
            if not stats["success"] or not np.all(np.isfinite(w)):
                return None, stats
            z_next = w[self.direct.z_index[1:]]
        else:
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
            z_next = x[self._z_next]
            w = np.zeros(self.layout.nw)
            w[keep] = x
        y = self.C @ z_next.T  # (ns, N): the limited outputs on z_1 .. z_N
        if np.any(y > self.c_hi[:, None]) or np.any(y < self.c_lo[:, None]):
            return None, stats
        return w, stats


class HpipmStages:
    """The smaller QP solved by :class:`~flexctrl.control.nmpc.hpipm_ocp.HpipmOCP`.

    Its data are moved from the whole QP's arrays.  The whole QP's shooting rows read
    ``A_k z_k + B_k v_k - z_{k+1} = lba_k``, so HPIPM's ``x_{k+1} = A_k x_k + B_k u_k + b_k``
    has ``b_k = -lba_k``; ``z_0`` is fixed by its bounds (``lbx = ubx = z_0``) and eliminated.
    The stage costs are the Hessian's diagonal blocks ``Q_k = H[z_k, z_k]``,
    ``R_k = H[v_k, v_k]`` (the NMPC's has no cross terms; one with them is refused), halved as
    ``casadi.conic`` hands them to HPIPM; the inputs' bounds are read from ``lbx, ubx`` every
    solve.  Any other bound on a state (there is none in the NMPC's QP) is refused when the
    data are read, not dropped.

    Parameters
    ----------
    layout : flexctrl.control.nmpc.casadi_functions.Layout
        The whole QP's variables.
    H : ndarray
        The whole QP's Hessian (dense).
    numbered : casadi.DM
        The whole constraint matrix's sparsity holding its nonzeros' numbers (1-based).
    rows : ndarray of int
        The whole QP's shooting rows.
    options : dict
        HPIPM's options (:func:`hpipm_options`' ``"hpipm"`` entry).

    Raises
    ------
    HpipmUnavailable
        When CasADi's ``libhpipm`` cannot be loaded.
    """

    def __init__(self, layout, H: np.ndarray, numbered: ca.DM, rows: np.ndarray, options: dict):
        n, m, N = layout.n, layout.m, layout.N
        self.layout = layout
        self.ocp = HpipmOCP(N, n, m, options)
        self.z_index = np.array([layout.z[k] for k in range(N + 1)])  # (N + 1, n)
        self.v_index = np.array([layout.v[k] for k in range(N)])  # (N, m)
        # ``numbered``: the whole A's sparsity holding its nonzeros' numbers (1-based; 0 a
        # structural zero)
        nnz = numbered.nnz()
        index = np.array(ca.densify(numbered), dtype=float).astype(np.int64) - 1
        index[index < 0] = nnz  # the sentinel entry: 0
        shooting = rows.reshape(N, n)
        # HPIPM's column-major blocks as C-ordered (cols, rows) arrays: A_k[i, j] at [k, j, i]
        self._ia = np.stack([index[np.ix_(shooting[k], self.z_index[k])].T for k in range(N)])
        self._ib = np.stack([index[np.ix_(shooting[k], self.v_index[k])].T for k in range(N)])
        self._shooting = shooting
        self._a = np.zeros(nnz + 1)
        ocp = self.ocp
        blocks = np.zeros_like(H, dtype=bool)
        for k in range(N + 1):
            z = self.z_index[k]
            blocks[np.ix_(z, z)] = True
            if k > 0:
                ocp.Q[k] = 0.5 * H[np.ix_(z, z)].T
            if k < N:
                v = self.v_index[k]
                blocks[np.ix_(v, v)] = True
                ocp.R[k] = 0.5 * H[np.ix_(v, v)].T
        kept = np.zeros(layout.nw, dtype=bool)
        kept[self.z_index.ravel()] = kept[self.v_index.ravel()] = True
        if np.any(H[np.ix_(kept, kept)][~blocks[np.ix_(kept, kept)]] != 0.0):
            raise ValueError(
                "the direct HPIPM path takes a Hessian without cross terms between stages, "
                "states and inputs (the NMPC's has none)"
            )
        state_bounds = np.ones(layout.nw, dtype=bool)
        state_bounds[self.v_index.ravel()] = False
        state_bounds[self.z_index[0]] = False
        slack = np.zeros(layout.nw, dtype=bool)
        slack[layout.s.ravel()] = True
        self._state_bounds = np.flatnonzero(state_bounds & ~slack)

    def solve(
        self,
        a: np.ndarray,
        lba: np.ndarray,
        g: np.ndarray,
        lbx: np.ndarray,
        ubx: np.ndarray,
        w0: np.ndarray,
    ) -> tuple[np.ndarray, dict]:
        """The smaller QP's solution as the whole QP's ``w`` (zero slacks) and HPIPM's statistics.

        Raises
        ------
        ValueError
            ``z_0``'s bounds differ (``lbx != ubx``) or another state has a finite bound.
        """
        ocp, N = self.ocp, self.layout.N
        z0 = lbx[self.z_index[0]]
        if (
            not np.array_equal(z0, ubx[self.z_index[0]])
            or np.any(np.isfinite(lbx[self._state_bounds]))
            or np.any(np.isfinite(ubx[self._state_bounds]))
        ):
            raise ValueError(
                "the direct HPIPM path takes z_0 fixed and only the inputs bounded; "
                "the NMPC's QP has no others"
            )
        self._a[:-1] = a
        ocp.A[:] = self._a[self._ia]
        ocp.B[:] = self._a[self._ib]
        ocp.b[:] = -lba[self._shooting]
        ocp.b[0] += ocp.A[0].T @ z0
        ocp.q[1:] = 0.5 * g[self.z_index[1:]]
        ocp.r[:N] = 0.5 * g[self.v_index]
        ocp.lbu[:N] = lbx[self.v_index]
        ocp.ubu[:N] = ubx[self.v_index]
        ocp.u[:N] = w0[self.v_index]
        ocp.x[1:] = w0[self.z_index[1:]]
        stats = ocp.solve()
        w = np.zeros(self.layout.nw)
        w[self.z_index[0]] = z0
        w[self.v_index] = ocp.u[:N]
        w[self.z_index[1:]] = ocp.x[1:]
        return w, stats


__all__ = ["ScreenedQP", "HpipmStages", "hpipm_options"]
