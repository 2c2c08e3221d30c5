"""The RTI's two calls per sample, linearize-and-assemble then the QP, through bound buffers.

:class:`BoundRTICalls` binds ``prepare(z0, w) -> (a, lba, uba)`` and the QP solver to
numpy arrays once per controller: ``prepare`` writes the constraint matrix and bounds
straight into the arrays the QP reads, the linearization trajectory ``w`` is also the
QP's start ``x0``, and the Hessian's entries are bound once (the QP's buffer is renewed per
solve, as an ordinary call's memory is: :class:`~flexctrl.sim.bound.BoundFunction`), so no
vector is converted to a CasADi ``DM`` and back per sample.  With a
:class:`~flexctrl.control.nmpc.screened_qp.ScreenedQP` the QP without its soft rows is tried
first and the whole QP solved only when the soft rows do not hold.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from flexctrl.control.nmpc.screened_qp import ScreenedQP
from flexctrl.sim.bound import BoundFunction


class BoundRTICalls:
    """``prepare`` and ``qp`` bound to shared arrays (see the module docstring); one per controller."""

    def __init__(
        self, prepare: ca.Function, qp: ca.Function, H: ca.DM, screen: ScreenedQP | None = None
    ):
        # : the QP without its soft rows, tried first (:mod:`flexctrl.control.nmpc.screened_qp`);
        # samples it served
        self.screen, self.screened, self.solves = screen, 0, 0
        if qp.sparsity_in("a") != prepare.sparsity_out("a") or qp.sparsity_in("h") != H.sparsity():
            raise ValueError(
                "the QP solver's sparsity differs from its data's: build them together (nmpc._build)"
            )
        self._w = np.zeros(prepare.nnz_in("w"))
        self._a = np.zeros(prepare.nnz_out("a"))
        self._lba, self._uba = np.zeros(prepare.nnz_out("lba")), np.zeros(prepare.nnz_out("uba"))
        data = {"a": self._a, "lba": self._lba, "uba": self._uba}
        self._prepare = BoundFunction(prepare, {"w": self._w, **data})
        # renewed per solve: HPIPM would otherwise warm-start its multipliers from the last solve's
        # work memory
        self._qp = BoundFunction(
            qp, {"h": np.array(H.nonzeros(), dtype=float), "x0": self._w, **data}, renew=True
        )
        self._z0 = self._prepare.arrays["z0"]
        self._g, self._lbx, self._ubx = (self._qp.arrays[k] for k in ("g", "lbx", "ubx"))
        self._x = self._qp.arrays["x"].reshape(-1)

    def linearize(
        self, z0: np.ndarray, w0: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(a, lba, uba)`` along ``w0`` from ``z0``: the bound arrays themselves (valid until the next call)."""
        self._z0[:] = z0
        self._w[:] = w0
        self._prepare.evaluate()
        return self._a, self._lba, self._uba

    def solve(self, g: np.ndarray, lbx: np.ndarray, ubx: np.ndarray) -> tuple[np.ndarray, dict]:
        """The QP's solution (a copy) and the solver's statistics, on the data of the last :meth:`linearise`."""
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


__all__ = ["BoundRTICalls"]
