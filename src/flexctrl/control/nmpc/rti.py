"""One real-time iteration of the NMPC: linearize and assemble along a trajectory, then the QP.

:class:`BoundRTICalls` binds ``prepare(z0, w) -> (a, lba, uba)`` and the QP solver to
numpy arrays once per controller: ``prepare`` writes the constraint matrix and bounds
straight into the arrays the QP reads, the linearization trajectory ``w`` is also the
QP's start ``x0``, and the Hessian's entries are bound once (the QP's buffer is renewed per
solve, as an ordinary call's memory is: :class:`~flexctrl.sim.bound.BoundFunction`), so no
vector is converted to a CasADi ``DM`` and back per sample.  With a
:class:`~flexctrl.control.nmpc.screened_qp.ScreenedQP` the QP without its soft rows is tried
first and the whole QP solved only when the soft rows do not hold.

:func:`rti_step` makes the two calls and turns every numerical failure into an unsuccessful
:class:`~flexctrl.control.mpc.qp_backends.Solution` with its reason, never an exception.
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from flexctrl.control.mpc.qp_backends import Solution
from flexctrl.control.nmpc.screened_qp import ScreenedQP
from flexctrl.sim.bound import BoundFunction


class BoundRTICalls:
    """``prepare`` and ``qp`` bound to shared arrays (module docstring); one per controller.

    Parameters
    ----------
    prepare : casadi.Function
        ``prepare(z0, w) -> (a, lba, uba)``: the QP's constraint matrix and bounds along ``w``.
    qp : casadi.Function
        The ``casadi.conic`` solver of the whole QP (built with ``prepare``'s sparsity).
    H : casadi.DM
        The QP's Hessian.
    screen : ScreenedQP, optional
        The QP without its soft rows, tried first.

    Attributes
    ----------
    screened, solves : int
        Samples the screened QP served, and samples solved.
    """

    def __init__(
        self, prepare: ca.Function, qp: ca.Function, H: ca.DM, screen: ScreenedQP | None = None
    ):
        self.screen, self.screened, self.solves = screen, 0, 0
        if qp.sparsity_in("a") != prepare.sparsity_out("a") or qp.sparsity_in("h") != H.sparsity():
            raise ValueError(
                "the QP solver's sparsity differs from its data's: build them together "
                "(flexctrl.control.nmpc.casadi_functions.build_functions)"
            )
        self._w = np.zeros(prepare.nnz_in("w"))
        self._a = np.zeros(prepare.nnz_out("a"))
        self._lba, self._uba = np.zeros(prepare.nnz_out("lba")), np.zeros(prepare.nnz_out("uba"))
        data = {"a": self._a, "lba": self._lba, "uba": self._uba}
        self._prepare = BoundFunction(prepare, {"w": self._w, **data})
        # renewed per solve: HPIPM would otherwise warm-start its multipliers from the last
        # solve's work memory
        self._qp = BoundFunction(
            qp, {"h": np.array(H.nonzeros(), dtype=float), "x0": self._w, **data}, renew=True
        )
        self._z0 = self._prepare.arrays["z0"]
        self._g, self._lbx, self._ubx = (self._qp.arrays[k] for k in ("g", "lbx", "ubx"))
        self._x = self._qp.arrays["x"].reshape(-1)

    def linearize(
        self, z0: np.ndarray, w0: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(a, lba, uba)`` along ``w0`` from the scaled state ``z0``.

        The bound arrays themselves, valid until the next call.
        """
        self._z0[:] = z0
        self._w[:] = w0
        self._prepare.evaluate()
        return self._a, self._lba, self._uba

    def solve(self, g: np.ndarray, lbx: np.ndarray, ubx: np.ndarray) -> tuple[np.ndarray, dict]:
        """The QP's solution (a copy) and the solver's statistics, on the last linearization.

        Parameters
        ----------
        g : ndarray
            The linear cost.
        lbx, ubx : ndarray
            The variables' bounds.

        Returns
        -------
        tuple
            ``(w, stats)``.
        """
        self.solves += 1
        if self.screen is not None:
            w, stats = self.screen.solve(self._a, self._lba, self._uba, g, lbx, ubx, self._w)
            if w is not None:
                self.screened += 1
                return w, stats
        self._g[:] = g
        self._lbx[:] = lbx
        self._ubx[:] = ubx
        self._qp.evaluate()
        return self._x.copy(), self._qp.stats()


def _values(v) -> np.ndarray:
    """The entries of a vector (a DM's stored entries: one list, cheaper than numpy's copy)."""
    return (
        np.array(v.nonzeros(), dtype=float)
        if isinstance(v, ca.DM)
        else np.asarray(v, dtype=float).ravel()
    )


def qp_data_problem(w0: np.ndarray, a, lba, uba) -> str:
    """What makes the RTI's QP data unusable, or ``""``.

    Infinite bounds are legitimate (one-sided soft rows); NaN anywhere, a non-finite
    linearization point or constraint matrix, ``lba = +inf`` or ``uba = -inf`` are not
    (HPIPM would abort with an assertion).

    Parameters
    ----------
    w0 : ndarray
        The linearization trajectory.
    a, lba, uba : ndarray or casadi.DM
        The constraint matrix's entries and the rows' bounds.

    Returns
    -------
    str
        The reason, or ``""`` when the data are usable.
    """
    if not np.all(np.isfinite(w0)):
        return "non-finite linearisation trajectory"
    if not (
        a.is_regular() if isinstance(a, ca.DM) else np.all(np.isfinite(np.asarray(a, dtype=float)))
    ):
        return "non-finite sensitivities"
    lo, hi = _values(lba), _values(uba)
    if np.any(np.isnan(lo)) or np.any(np.isnan(hi)):
        return "NaN in the constraint bounds"
    if np.any(lo == np.inf) or np.any(hi == -np.inf):
        return "infinite shooting gap"
    return ""


def rti_step(
    calls: BoundRTICalls,
    z0: np.ndarray,
    w0: np.ndarray,
    g: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray],
    timing: dict[str, list[float]],
) -> Solution:
    """One RTI step: linearize along ``w0``, assemble and solve the QP.

    Never raises for numerical trouble: non-finite QP data (a shooting interval or its
    sensitivities that overflowed along ``w0``), an exception of the QP solver and an
    unsuccessful or non-finite solution all return ``ok = False`` with the reason in
    ``status``.

    Parameters
    ----------
    calls : BoundRTICalls
        The controller's bound calls.
    z0 : ndarray
        The scaled initial state.
    w0 : ndarray
        The linearization trajectory (and the QP's start).
    g : ndarray
        The QP's linear cost.
    bounds : tuple of ndarray
        ``(lbx, ubx)``, the variables' bounds.
    timing : dict
        ``"linearize_qp"`` and ``"qp"`` lists, each given this step's wall time (s).

    Returns
    -------
    Solution
        ``w`` is NaN when no QP was solved.
    """
    start = time.perf_counter()
    a, lba, uba = calls.linearize(z0, w0)
    mid = time.perf_counter()
    timing["linearize_qp"].append(mid - start)
    problem = qp_data_problem(w0, a, lba, uba)
    if problem:
        timing["qp"].append(0.0)
        nan = np.full_like(w0, np.nan)
        elapsed = time.perf_counter() - start
        return Solution(False, f"non-finite QP data ({problem})", nan, 0, elapsed)
    try:
        w, stats = calls.solve(g, *bounds)
    except RuntimeError as exc:  # CasADi's checks (e.g. HPIPM's ill-posed bounds) raise
        end = time.perf_counter()
        timing["qp"].append(end - mid)
        text = " ".join(str(exc).split())
        nan = np.full_like(w0, np.nan)
        return Solution(False, f"QP solver error: {text[-300:]}", nan, 0, end - start)
    end = time.perf_counter()
    timing["qp"].append(end - mid)
    ok = bool(stats.get("success", False)) and bool(np.all(np.isfinite(w)))
    if ok:
        status = "solved"
    elif not np.all(np.isfinite(w)):
        status = "non-finite QP solution"
    else:
        status = str(stats.get("unified_return_status", stats.get("return_status", "failed")))
    return Solution(ok, status, w, int(stats.get("iter_count", -1) or -1), end - start)


__all__ = ["BoundRTICalls", "qp_data_problem", "rti_step"]
