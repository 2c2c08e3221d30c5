"""CasADi Functions whose numeric constants become an input, so one compiled library serves many models.

A frozen-modes model bakes its modal constants (which depend on the payload and on
the configuration the modes were computed at) into ``f``; C code generated from it
differs per configuration, so a study over configurations would compile once per run.
:func:`constants_as_parameters` rebuilds such a Function with its constants as a
vector input: models whose graphs differ only in constant values then share one
compiled library (the cache key is a hash of the generated code).  Used by the NMPC
(:mod:`flexctrl.control.nmpc`), the closed-loop plant step (:mod:`flexctrl.loop.plant_step`)
and the Jacobians shared by a model structure (:mod:`flexctrl.dynamics.jacobians`).
:class:`Memo` keeps what is built from such a lifted Function once per process.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any, Callable

import casadi as ca
import numpy as np

from flexctrl.dynamics.model import derived


class Memo:
    """Values built from a content key, kept once per process (least recently used beyond ``size``).

    For what is a pure function of its key's content (a Function built from another's
    serialized form): the value for one model serves every other of the same structure.
    """

    def __init__(self, size: int):
        self.size = size
        self._built: OrderedDict[str, Any] = OrderedDict()

    def get(self, key: str, build: Callable[[], Any]) -> tuple[Any, bool]:
        """``(value, reused)``: ``build()`` the first time ``key`` is asked for, the kept value after."""
        if key in self._built:
            self._built.move_to_end(key)
            return self._built[key], True
        value = build()
        self._built[key] = value
        while len(self._built) > self.size:
            self._built.popitem(last=False)
        return value, False

    def clear(self) -> None:
        """Forget every kept value."""
        self._built.clear()


def try_expand(fun: ca.Function) -> ca.Function:
    """``fun`` rewritten as an SX Function when possible (faster to evaluate and compile)."""
    if fun.is_a("SXFunction"):
        return fun
    try:
        return fun.expand()
    except RuntimeError:
        return fun


def parametric(model, name: str, fun, *, per_use: bool = False) -> tuple[ca.Function, np.ndarray]:
    """:func:`constants_as_parameters` of ``fun()`` (a Function of ``model`` called ``name``), once per model.

    Kept with the model (:func:`~flexctrl.dynamics.model.derived`): every plant step count,
    output-map length and reference table of one model lifts its constants once (the lift
    walks the whole expression graph in Python).
    """
    return derived(model, ("parametric", name, per_use), lambda: constants_as_parameters(fun(), per_use=per_use))


def constants_as_parameters(fun: ca.Function, *, per_use: bool = False) -> tuple[ca.Function, np.ndarray]:
    """``fun`` rebuilt with every numeric constant of its expression graph turned into an input.

    A frozen-modes model bakes its modal constants (which depend on the payload and on
    the configuration the modes were computed at) into ``f``; code generated from it
    would differ per configuration.  The rebuilt Function ``fp(*inputs, c)`` computes
    the same operations in the same order with ``c`` the vector of the graph's constants,
    so two models whose graphs differ only in constant values share one compiled
    library.

    Parameters
    ----------
    fun : casadi.Function
        An SX Function (MX Functions are expanded first).
    per_use : bool
        One entry of ``c`` per USE of a constant (each operand and output that is a
        constant) instead of one per constant node.  A graph built with common
        subexpression elimination merges constants whose values happen to coincide
        (at the straight arm, say), so its node count, and the code generated from it,
        depend on the values; per use the structure depends on the operations alone.

    Returns
    -------
    fp : casadi.Function
        ``fun``'s inputs plus ``c`` (last); the same outputs.  ``fun`` itself (and an empty
        ``c``) when the graph cannot be rebuilt (calls to other Functions, free
        symbols) or the rebuilt Function does not reproduce ``fun``.
    c : ndarray
        The constants, in the order of the graph.
    """
    f = try_expand(fun)
    if not f.is_a("SXFunction") or f.has_free():
        return fun, np.zeros(0)
    ops = [f.instruction_id(k) for k in range(f.n_instructions())]
    n_const = (sum(len(f.instruction_input(k)) for k, op in enumerate(ops) if op not in (ca.OP_INPUT, ca.OP_CONST))
               if per_use else ops.count(ca.OP_CONST))
    ins = [ca.SX.sym(f.name_in(i), f.sparsity_in(i)) for i in range(f.n_in())]
    c = ca.SX.sym("c", n_const)
    outs = [[ca.SX(0)] * f.nnz_out(i) for i in range(f.n_out())]
    work: dict[int, ca.SX] = {}
    constant: dict[int, float] = {}  # per use: work slots holding a constant, turned into an entry of c when read
    values = []

    def read(slot):
        if slot not in constant:
            return work[slot]
        values.append(constant[slot])
        return c[len(values) - 1]

    for k, op in enumerate(ops):
        arg, res = f.instruction_input(k), f.instruction_output(k)
        if op == ca.OP_INPUT:
            work[res[0]] = ins[arg[0]].nz[arg[1]]
            constant.pop(res[0], None)
        elif op == ca.OP_OUTPUT:
            outs[res[0]][res[1]] = read(arg[0])
        elif op == ca.OP_CONST and per_use:
            constant[res[0]] = f.instruction_constant(k)
        elif op == ca.OP_CONST:
            work[res[0]] = c[len(values)]
            values.append(f.instruction_constant(k))
        elif len(arg) in (1, 2) and op not in (ca.OP_CALL, ca.OP_PARAMETER):
            operands = [read(a) for a in arg]
            work[res[0]] = ca.SX.unary(op, *operands) if len(arg) == 1 else ca.SX.binary(op, *operands)
            constant.pop(res[0], None)
        else:
            return fun, np.zeros(0)
    c = c[: len(values)]
    out = [ca.SX(f.sparsity_out(i), ca.vertcat(*outs[i]) if outs[i] else ca.SX(0, 1)) for i in range(f.n_out())]
    fp = ca.Function(f"{f.name()}_p", [*ins, c], out, [*f.name_in(), "c"], f.name_out())
    const = np.array(values, dtype=float)
    # the rebuilt graph must reproduce the original at a generic point
    rng = np.random.default_rng(0)
    args = [rng.uniform(-0.5, 0.5, f.sparsity_in(i).shape) for i in range(f.n_in())]
    for a, b in zip(f(*args) if f.n_out() > 1 else [f(*args)], fp(*args, const) if f.n_out() > 1 else [fp(*args, const)]):
        a, b = np.array(a, dtype=float), np.array(b, dtype=float)
        if not np.allclose(a, b, rtol=1e-12, atol=1e-12 * max(1.0, float(np.max(np.abs(a), initial=0.0)))):
            return fun, np.zeros(0)
    return fp, const
