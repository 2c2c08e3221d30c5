"""QP solvers for the linear MPC: OSQP (warm-started, vectors updated only) or casadi.conic.

Both take the QP of :mod:`flexctrl.control.mpc.qp` once, then per sample the scaled state,
the previous solution and the reference shifts, and give a :class:`Solution`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np
import osqp
import scipy.sparse as sp

from flexctrl.control.mpc.qp import QP
from flexctrl.spec.mpc_settings import MPCSettings


@dataclass
class Solution:
    """What a QP solver returned.

    Attributes
    ----------
    ok : bool
        Whether the solution may be used.
    status : str
        The solver's status (``"solved"`` when ``ok``).
    w : ndarray
        The QP's variables, scaled.
    iterations : int
        Solver iterations (-1 when the solver does not say).
    solve_time : float
        The solver's own time, s.
    """

    ok: bool
    status: str
    w: np.ndarray
    iterations: int
    solve_time: float


class OSQPBackend:
    """OSQP with the variable bounds as extra rows; only ``q``/``l``/``u`` are ever updated.

    Parameters
    ----------
    qp : QP
        The QP.
    settings : OSQPSettings
        OSQP's settings.
    accept_inaccurate : bool
        Use OSQP's "solved inaccurate" solutions.
    warm_start : {"shift", "previous", "none"}
        OSQP's start each sample.
    """

    name = "osqp"

    def __init__(self, qp: QP, settings, accept_inaccurate: bool, warm_start: str):
        self.qp = qp
        nw = qp.H.shape[0]
        has_bound = np.isfinite(qp.lbx) | np.isfinite(qp.ubx)
        has_bound[qp.ix0] = True  # the initial state is fixed by its bounds
        bounded = np.flatnonzero(has_bound)
        self.bounded = bounded
        box = sp.csc_matrix(
            (np.ones(bounded.size), (np.arange(bounded.size), bounded)), shape=(bounded.size, nw)
        )
        self.A = sp.vstack([qp.A, box], format="csc")
        self.n_rows = qp.A.shape[0]
        inv_pos = np.full(nw, -1)
        inv_pos[bounded] = np.arange(bounded.size)
        # dual shift: general rows by shift_a, box rows follow their variables
        box_shift = inv_pos[qp.shift_w[bounded]]
        self.shift_y = np.r_[
            qp.shift_a, self.n_rows + np.where(box_shift >= 0, box_shift, np.arange(bounded.size))
        ].astype(int)
        self.accept = {1} | ({2} if accept_inaccurate else set())
        self.warm = warm_start
        g, lba, uba, lbx, ubx = qp.vectors(np.zeros(qp.n_state))
        self._setup = (
            (
                sp.triu(qp.H, format="csc"),
                g,
                self.A,
                np.r_[lba, lbx[bounded]],
                np.r_[uba, ubx[bounded]],
            ),
            dict(verbose=False, warm_starting=warm_start != "none", **settings.as_dict()),
        )
        self.reset()

    def reset(self) -> None:
        """A new OSQP workspace as designed: no iterate to warm-start from, ``rho`` as set.

        OSQP keeps its last primal and dual iterates (its internal warm start) and the
        ``rho`` its adaptation reached in the workspace, so without this a run would
        depend on the runs solved before it with the same controller.
        """
        args, opts = self._setup
        self.solver = osqp.OSQP()
        self.solver.setup(*args, **opts)
        self.y = None

    def solve(
        self,
        z: np.ndarray,
        w_prev: np.ndarray | None,
        dv: np.ndarray | None = None,
        dc: np.ndarray | None = None,
        release: np.ndarray | None = None,
        du: np.ndarray | None = None,
    ) -> Solution:
        g, lba, uba, lbx, ubx = self.qp.vectors(z, dv, dc, release, du)
        self.solver.update(q=g, l=np.r_[lba, lbx[self.bounded]], u=np.r_[uba, ubx[self.bounded]])
        if self.warm == "shift" and w_prev is not None and self.y is not None:
            self.solver.warm_start(x=w_prev[self.qp.shift_w], y=self.y[self.shift_y])
        res = self.solver.solve(raise_error=False)
        status = res.info.status_val
        self.y = res.y
        ok = status in self.accept
        return Solution(ok, res.info.status, res.x, int(res.info.iter), float(res.info.run_time))


class ConicBackend:
    """A QP solver shipped with CasADi (``casadi.conic``): hpipm, daqp, qpoases, osqp.

    Parameters
    ----------
    qp : QP
        The QP (HPIPM needs the sparse stage-wise form).
    name : str
        The ``casadi.conic`` plugin.
    options : dict, optional
        Options of the plugin, on top of the defaults set here.
    """

    def __init__(self, qp: QP, name: str, options: dict | None = None):
        self.qp = qp
        self.name = name
        opts = dict(options or {})
        if name == "hpipm":
            opts.update({key: qp.stages[key] for key in ("N", "nx", "nu", "ng")})
            opts.setdefault(
                "hpipm",
                {
                    "mode": "speed",
                    "iter_max": 30,
                    "res_g_max": 1e-5,
                    "res_b_max": 1e-6,
                    "res_d_max": 1e-6,
                    "res_m_max": 1e-6,
                },
            )
        elif name == "qpoases":
            opts.setdefault("printLevel", "none")
            opts.setdefault("sparse", False)
        elif name == "osqp":
            opts.setdefault("osqp", {"verbose": False})
        opts.setdefault("error_on_fail", False)
        self.H = ca.DM(qp.H)
        self.Am = ca.DM(qp.A) if qp.A.shape[0] else ca.DM(0, qp.H.shape[0])
        self.options = opts
        self.reset()

    def reset(self) -> None:
        """A new solver instance: qpOASES, for one, hot-starts from its last working set."""
        self.solver = ca.conic(
            "mpc_qp", self.name, {"h": self.H.sparsity(), "a": self.Am.sparsity()}, self.options
        )

    def solve(
        self,
        z: np.ndarray,
        w_prev: np.ndarray | None,
        dv: np.ndarray | None = None,
        dc: np.ndarray | None = None,
        release: np.ndarray | None = None,
        du: np.ndarray | None = None,
    ) -> Solution:
        g, lba, uba, lbx, ubx = self.qp.vectors(z, dv, dc, release, du)
        args = {"h": self.H, "g": g, "a": self.Am, "lba": lba, "uba": uba, "lbx": lbx, "ubx": ubx}
        if w_prev is not None:
            args["x0"] = w_prev[self.qp.shift_w]
        out = self.solver(**args)
        stats = self.solver.stats()
        w = np.array(out["x"], dtype=float).ravel()
        ok = bool(stats.get("success", False)) and bool(np.all(np.isfinite(w)))
        status = (
            "solved"
            if ok
            else str(stats.get("unified_return_status", stats.get("return_status", "failed")))
        )
        return Solution(
            ok,
            status,
            w,
            int(stats.get("iter_count", -1) or -1),
            float(stats.get("t_wall_solver", stats.get("t_wall_total", math.nan))),
        )


def make_backend(qp: QP, settings: MPCSettings):
    """The QP backend named by ``settings.backend``.

    Parameters
    ----------
    qp : QP
        The QP.
    settings : MPCSettings
        Its ``backend`` and, for OSQP, its OSQP settings.

    Returns
    -------
    OSQPBackend or ConicBackend
    """
    if settings.backend == "osqp":
        return OSQPBackend(qp, settings.osqp, settings.accept_inaccurate, settings.warm_start)
    return ConicBackend(qp, settings.backend)


__all__ = ["Solution", "OSQPBackend", "ConicBackend", "make_backend"]
