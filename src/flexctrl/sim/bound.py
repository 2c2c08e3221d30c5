"""CasADi Functions called through buffers bound to numpy arrays: no DM conversions per call.

Calling a CasADi Function from Python converts every numpy input to a ``DM`` and every
output back, which dominates small compiled calls made every sample.  A ``FunctionBuffer`` reads its
inputs from and writes its outputs to memory bound once.  CasADi is column-major, so an input or
output of shape (rows, cols) is a C-ordered numpy array of shape (cols, rows): pass states as rows,
get results as rows.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import casadi as ca
import numpy as np


def evaluate(fun: ca.Function, *args: np.ndarray) -> list[np.ndarray]:
    """``fun(*args)`` through a buffer bound to numpy arrays for this one call (results as rows).

    Parameters
    ----------
    fun : casadi.Function
        The Function to evaluate.
    *args : numpy.ndarray
        Its inputs, each broadcast to the input's number of nonzeros.

    Returns
    -------
    list of numpy.ndarray
        The outputs, an output of shape (rows, cols) as (cols, rows).
    """
    buffer, trigger = fun.buffer()
    inputs = [
        np.ascontiguousarray(
            np.broadcast_to(np.asarray(a, dtype=float).reshape(-1), (fun.nnz_in(i),))
        )
        for i, a in enumerate(args)
    ]
    outputs = [np.zeros((fun.size2_out(i), fun.size1_out(i))) for i in range(fun.n_out())]
    bind_buffer(buffer, inputs, outputs)
    trigger()
    return outputs


def bind_buffer(
    buffer: ca.FunctionBuffer, inputs: Sequence[np.ndarray], outputs: Sequence[np.ndarray]
) -> list[memoryview]:
    """Bind ``buffer``'s inputs and outputs to numpy arrays (C-ordered float64, kept alive).

    Parameters
    ----------
    buffer : casadi.FunctionBuffer
        The buffer of a Function (``fun.buffer()[0]``).
    inputs, outputs : sequence of numpy.ndarray
        One array per input and per output, in order.

    Returns
    -------
    list of memoryview
        The views bound; the arrays must outlive the binding.
    """
    views = [_view(a) for a in (*inputs, *outputs)]
    for i, view in enumerate(views[: len(inputs)]):
        buffer.set_arg(i, view)  # type: ignore[call-arg]  # stub has C's (ptr, size)
    for i, view in enumerate(views[len(inputs) :]):
        buffer.set_res(i, view)  # type: ignore[call-arg]  # stub has C's (ptr, size)
    return views


def _view(array: np.ndarray) -> memoryview:
    return memoryview(array)  # type: ignore[arg-type]  # numpy stubs: __buffer__ on 3.12+ only


class BoundFunction:
    """A CasADi Function bound once to numpy arrays, for calls in a loop.

    ``bound(*args)`` copies the inputs into the bound arrays, evaluates and returns copies of
    the outputs as rows (an output of shape (rows, cols) comes back as (cols, rows), as from
    :func:`evaluate`).  No CasADi matrices are made per call, which is most of the cost of a
    small Function's ordinary call; the values are the same (the same compiled code).

    ``shared`` binds named inputs or outputs to arrays the caller owns (C-ordered float64
    with the entries of the Function's sparsity, stored nonzeros only), so one Function's
    output can be another's input with no copy: :meth:`evaluate` then runs on whatever the
    arrays hold and :attr:`arrays` gives every bound array by name.  Not picklable: make
    one per run (or per controller, dropped when it is pickled).

    ``renew``: a new buffer, so fresh work memory, for every evaluation.  A buffer keeps
    its work vector between calls where an ordinary call starts from new memory, and some
    Functions read it: CasADi's HPIPM interface, warm-started, then takes the previous
    solve's multipliers and slacks from it (other iterates from the second sample on),
    where an ordinary call starts them afresh.

    Parameters
    ----------
    fun : casadi.Function
        The Function to bind.
    shared : mapping of str to numpy.ndarray, optional
        Arrays the caller owns, bound to the inputs or outputs of these names.
    renew : bool
        A new buffer (fresh work memory) for every evaluation.
    """

    def __init__(
        self, fun: ca.Function, shared: Mapping[str, np.ndarray] | None = None, renew: bool = False
    ):
        self.function = fun
        self.renew = renew
        shared = dict(shared or {})
        unknown = set(shared) - set(fun.name_in()) - set(fun.name_out())
        if unknown:
            raise ValueError(
                f"Function {fun.name()!r} has no input or output {sorted(unknown)}; "
                f"allowed: {fun.name_in() + fun.name_out()}"
            )
        self._buffer, self._trigger = fun.buffer()
        self._inputs = [
            self._bind(shared, fun.name_in(i), fun.nnz_in(i), (fun.nnz_in(i),))
            for i in range(fun.n_in())
        ]
        self._outputs = [
            self._bind(
                shared,
                fun.name_out(i),
                fun.nnz_out(i),
                (fun.size2_out(i), fun.size1_out(i))
                if fun.nnz_out(i) == fun.numel_out(i)
                else (fun.nnz_out(i),),
            )
            for i in range(fun.n_out())
        ]
        self._views = bind_buffer(self._buffer, self._inputs, self._outputs)
        self.arrays = dict(zip(fun.name_in() + fun.name_out(), self._inputs + self._outputs))

    def _bind(
        self, shared: Mapping[str, np.ndarray], name: str, nnz: int, shape: tuple
    ) -> np.ndarray:
        if name not in shared:
            return np.zeros(shape)
        a = shared[name]
        if a.dtype != np.float64 or not a.flags.c_contiguous or a.size != nnz:
            raise ValueError(
                f"Function {self.function.name()!r}: the array bound to {name!r} must be C-ordered "
                f"float64 with {nnz} entries; got {a.dtype} {a.shape}"
            )
        return a

    def __call__(self, *args) -> list[np.ndarray]:
        for bound, value in zip(self._inputs, args):
            bound[:] = np.asarray(value, dtype=float).reshape(-1)
        self.evaluate()
        return [r.copy() for r in self._outputs]

    def evaluate(self) -> None:
        """Evaluate on the bound inputs as they are, into the bound outputs (raising as it does)."""
        if self.renew:
            self._buffer, self._trigger = self.function.buffer()
            self._views = bind_buffer(self._buffer, self._inputs, self._outputs)
        self._trigger()

    def stats(self) -> dict:
        """The last evaluation's statistics (a QP solver's ``success``, ``iter_count``, ...)."""
        return self._buffer.stats()


__all__ = ["BoundFunction", "evaluate"]
