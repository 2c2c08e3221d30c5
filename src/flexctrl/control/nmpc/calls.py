"""The RTI's two calls per sample, linearise-and-assemble then the QP, with or without bound
buffers.

:class:`BoundRTICalls` binds ``prepare(z0, w) -> (a, lba, uba)`` and the QP solver to
numpy arrays once per controller: ``prepare`` writes the constraint matrix and bounds
straight into the arrays the QP reads, the linearisation trajectory ``w`` is also the
QP's start ``x0``, and the Hessian's entries are bound once (the QP's buffer is renewed per
solve, as an ordinary call's memory is: :class:`~flexctrl.sim.bound.BoundFunction`).
With a :class:`~flexctrl.control.nmpc.screened_qp.ScreenedQP` the QP without its soft rows is
tried first and the whole QP solved only when the soft rows do not hold.  :class:`DMRTICalls` makes
the same two calls through CasADi's ordinary call (every vector converted to a ``DM`` and
back).  Same compiled code, same values to the bit; measured on the benchmark problem
(``flexctrl bench mpc``: 12 states, horizon 20, 372 QP variables), the conversions cost
0.6-0.9 ms a sample (the DM calls 3.00 / 2.42 ms against 2.36 / 1.55 ms bound, both with the
whole QP, interleaved / in blocks).  ``design_nmpc(..., bound_calls=False)`` keeps the DM path.
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


class DMRTICalls:
    """The same calls through CasADi's ordinary call: the slow path, kept to measure the bound one against."""

    def __init__(self, prepare: ca.Function, qp: ca.Function, H: ca.DM):
        self._prepare, self._qp, self._H = prepare, qp, H
        self._data: tuple = ()
        self._w0: np.ndarray | None = None

    def linearize(self, z0: np.ndarray, w0: np.ndarray) -> tuple:
        """``(a, lba, uba)`` along ``w0`` from ``z0`` (DMs)."""
        self._data, self._w0 = tuple(self._prepare(z0, w0)), w0
        return self._data

    def solve(self, g: np.ndarray, lbx: np.ndarray, ubx: np.ndarray) -> tuple[np.ndarray, dict]:
        """The QP's solution and the solver's statistics, on the data of the last :meth:`linearise`."""
        a, lba, uba = self._data
        out = self._qp(h=self._H, g=g, a=a, lba=lba, uba=uba, lbx=lbx, ubx=ubx, x0=self._w0)
        return np.array(out["x"], dtype=float).ravel(), self._qp.stats()


__all__ = ["BoundRTICalls", "DMRTICalls"]
