"""CasADi Functions whose numeric constants become an input: one compiled library, many models.

A frozen-modes model bakes its modal constants (which depend on the payload and on
the configuration the modes were computed at) into ``f``; C code generated from it
differs per configuration, so a study over configurations would compile once per run.
:func:`constants_as_parameters` rebuilds such a Function with its constants as a
vector input: models whose graphs differ only in constant values then share one
compiled library (the cache key is a hash of the generated code).  Used by the NMPC
(:mod:`flexctrl.control.nmpc.controller`), the closed-loop plant step
(:mod:`flexctrl.loop.plant_step`) and the Jacobians shared by a model structure
(:mod:`flexctrl.dynamics.jacobians`).  :class:`Memo` keeps what is built from such a lifted Function
once per process.
"""

from __future__ import annotations

import bisect
import hashlib
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any

import casadi as ca
import numpy as np

from flexctrl.dynamics.model import derived


class Memo:
    """Values built from a content key, kept once per process (least recently used beyond ``size``).

    For what is a pure function of its key's content (a Function built from another's
    serialized form): the value for one model serves every other of the same structure.

    Parameters
    ----------
    size : int
        Entries kept.
    """

    def __init__(self, size: int):
        self.size = size
        self._built: OrderedDict[Hashable, Any] = OrderedDict()
        self._lock = threading.Lock()  # a Dask worker may run two runs in threads

    def get(self, key: Hashable, build: Callable[[], Any]) -> tuple[Any, bool]:
        """``(value, reused)``: ``build()`` when ``key`` is first asked for, then the kept value."""
        value = self.lookup(key)
        if value is not None:
            return value, True
        value = build()
        self.keep(key, value)
        return value, False

    def lookup(self, key: Hashable) -> Any:
        """The value kept for ``key`` (now the most recently used), or None."""
        with self._lock:
            if key not in self._built:
                return None
            self._built.move_to_end(key)
            return self._built[key]

    def keep(self, key: Hashable, value: Any) -> None:
        """Keep ``value`` for ``key``, forgetting the least recently used beyond ``size``."""
        with self._lock:
            self._built[key] = value
            self._built.move_to_end(key)
            while len(self._built) > self.size:
                self._built.popitem(last=False)

    def clear(self) -> None:
        """Forget every kept value."""
        with self._lock:
            self._built.clear()


class ObjectMemo:
    """Values built from one object (a kept lifted Function), found again by the object's identity.

    A lift kept in :data:`LIFTED` is returned as the same object to every model of its
    structure, so what is built from it alone (its compiled library, the key of its
    Jacobian) can be kept with it: a later model skips building, serializing and loading
    again.  The object is held with its value, so its ``id`` cannot pass to another object
    while the entry lasts; least recently used beyond ``size``.

    Parameters
    ----------
    size : int
        Entries kept.
    """

    def __init__(self, size: int):
        self._memo = Memo(size)

    def get(self, owner: Any, tag: Any, build: Callable[[], Any]) -> Any:
        """``build()`` the first time ``(owner, tag)`` is asked for, the kept value after."""
        value = self.lookup(owner, tag)
        if value is None:
            value = build()
            self.keep(owner, tag, value)
        return value

    def lookup(self, owner: Any, tag: Any) -> Any:
        """The value kept for ``(owner, tag)``, or None."""
        kept = self._memo.lookup((id(owner), tag))
        return kept[1] if kept is not None and kept[0] is owner else None

    def keep(self, owner: Any, tag: Any, value: Any) -> None:
        """Keep ``value`` for ``(owner, tag)``, holding ``owner`` with it."""
        self._memo.keep((id(owner), tag), (owner, value))

    def clear(self) -> None:
        """Forget every kept value."""
        self._memo.clear()


#: What is built from a kept lifted Function alone, by its identity and a tag (:class:`ObjectMemo`).
FROM_LIFTED = ObjectMemo(32)


def try_expand(fun: ca.Function) -> ca.Function:
    """``fun`` rewritten as an SX Function when possible (faster to evaluate and compile).

    Parameters
    ----------
    fun : casadi.Function
        An MX or SX Function.

    Returns
    -------
    casadi.Function
        The SX form, or ``fun`` itself when it cannot be expanded.
    """
    if fun.is_a("SXFunction"):
        return fun
    try:
        return fun.expand()
    except RuntimeError:
        return fun


def parametric(model, name: str, fun, *, per_use: bool = False) -> tuple[ca.Function, np.ndarray]:
    """:func:`constants_as_parameters` of ``fun()``, ``model``'s Function ``name``, once per model.

    Kept with the model (:func:`~flexctrl.dynamics.model.derived`): every plant step count,
    output-map length and reference table of one model lifts its constants once (the lift
    walks the whole expression graph in Python).

    Parameters
    ----------
    model : Model
        The model the lift is kept with.
    name : str
        The Function's name, part of the key it is kept under.
    fun : callable
        ``fun()`` builds the Function, called only when no lift is kept.
    per_use : bool
        One constant per use, as in :func:`constants_as_parameters`.

    Returns
    -------
    tuple
        ``(fp, c)`` as :func:`constants_as_parameters` returns them.
    """
    return derived(
        model,
        ("parametric", name, per_use),
        lambda: constants_as_parameters(fun(), per_use=per_use),
    )


#: Lifted Functions by structure (:func:`structure_key`): ``(fp, sources)``, least recently used
#: beyond 16.
LIFTED = Memo(16)


def structure_key(f: ca.Function, ops: list[int], per_use: bool) -> str:
    """A hash of an SX Function's operations, its input and output sparsities and ``per_use``.

    It leaves out the operands' wiring, which costs a Python call per instruction to read
    (most of a lift's time): a kept lift found by this key is used only after it reproduces
    the Function (:func:`_reproduces`).
    Per use, the constant nodes are left out too: common subexpression elimination merges
    constants whose values coincide, so their count moves with the configuration while the
    lifted Function does not.

    Parameters
    ----------
    f : casadi.Function
        An SX Function.
    ops : list of int
        The operation code of each of its instructions.
    per_use : bool
        One constant per use (constant nodes left out of the key).

    Returns
    -------
    str
        A hexadecimal digest.
    """
    if (
        per_use
    ):  # constants as operands, not nodes: how many nodes hold them does not change the lift
        ops = [op for op in ops if op != ca.OP_CONST]
    h = hashlib.sha256(np.asarray(ops, dtype=np.int64).tobytes())
    for i in range(f.n_in()):
        h.update(f"in{i}:{f.name_in(i)}:{f.sparsity_in(i).hash()}".encode())
    for i in range(f.n_out()):
        h.update(f"out{i}:{f.name_out(i)}:{f.sparsity_out(i).hash()}".encode())
    h.update(f"name={f.name()}|per_use={per_use}".encode())
    return h.hexdigest()


def constants_as_parameters(
    fun: ca.Function, *, per_use: bool = False
) -> tuple[ca.Function, np.ndarray]:
    """``fun`` rebuilt with every numeric constant of its expression graph turned into an input.

    A frozen-modes model bakes its modal constants (which depend on the payload and on
    the configuration the modes were computed at) into ``f``; code generated from it
    would differ per configuration.  The rebuilt Function ``fp(*inputs, c)`` computes
    the same operations in the same order with ``c`` the vector of the graph's constants,
    so two models whose graphs differ only in constant values share one compiled
    library.

    A lift kept in this process (:data:`LIFTED`) serves every later Function with the same
    :func:`structure_key`: its constants are read from the instructions the kept lift
    records (one call per constant, not a walk of the graph and a rebuild), and the kept
    ``fp`` is returned once it reproduces ``fun`` at a generic point; otherwise the graph is
    lifted anew.  Either way ``fp`` has the same structure and ``c`` the same values.

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
    key = structure_key(f, ops, per_use)
    kept = LIFTED.lookup(key)
    if kept is not None:
        fp, sources, uses = kept
        const = _constants_per_use(f, ops, uses) if per_use else _constants(f, sources)
        if const is not None and _reproduces(f, fp, const):
            return fp, const
    lifted = _lift(f, ops, per_use)
    if lifted is None:
        return fun, np.zeros(0)
    fp, sources, uses = lifted
    const = _constants(f, sources)
    if not _reproduces(f, fp, const):
        return fun, np.zeros(0)
    LIFTED.keep(key, lifted)
    return fp, const


def _constants(f: ca.Function, sources: list[int]) -> np.ndarray:
    """The values of the constant instructions ``sources`` of ``f``, in that order."""
    return np.array([f.instruction_constant(k) for k in sources], dtype=float)


def _constants_per_use(
    f: ca.Function, ops: list[int], uses: list[tuple[int, int]]
) -> np.ndarray | None:
    """``c`` of a per-use lift from its ``uses`` (the ``j``-th non-constant instruction's operand
    ``pos``), reading only the constant instructions and the operands that are constants.

    Each such operand's value is the last constant written to its work slot before the
    instruction; None when no constant was (the graph is wired otherwise than the kept one's).
    """
    writes: dict[int, list[tuple[int, float]]] = {}
    for k, op in enumerate(ops):
        if op == ca.OP_CONST:
            writes.setdefault(f.instruction_output(k)[0], []).append((k, f.instruction_constant(k)))
    others = [k for k, op in enumerate(ops) if op != ca.OP_CONST]
    values = []
    for j, pos in uses:
        k = others[j]
        written = writes.get(f.instruction_input(k)[pos], ())
        i = bisect.bisect_left(written, (k, -np.inf)) - 1
        if i < 0:
            return None
        values.append(written[i][1])
    return np.array(values, dtype=float)


def _lift(
    f: ca.Function, ops: list[int], per_use: bool
) -> tuple[ca.Function, list[int], list] | None:
    """``(fp, sources, uses)``: ``f`` rebuilt with its constants as the last input, the constant
    instruction that gives each entry of ``c`` and, per use, where each entry is read (the
    ``j``-th non-constant instruction's operand ``pos``); None when an instruction cannot be
    rebuilt."""
    n_const = (
        sum(
            len(f.instruction_input(k))
            for k, op in enumerate(ops)
            if op not in (ca.OP_INPUT, ca.OP_CONST)
        )
        if per_use
        else ops.count(ca.OP_CONST)
    )
    ins = [ca.SX.sym(f.name_in(i), f.sparsity_in(i)) for i in range(f.n_in())]
    c = ca.SX.sym("c", n_const)
    outs = [[ca.SX(0)] * f.nnz_out(i) for i in range(f.n_out())]
    work: dict[int, ca.SX] = {}
    constant: dict[int, int] = {}  # per use: work slot -> the instruction of the constant it holds
    sources: list[int] = []
    uses: list[tuple[int, int]] = []
    j = -1  # index of the current instruction among the non-constant ones

    def read(slot, pos):
        if slot not in constant:
            return work[slot]
        sources.append(constant[slot])
        uses.append((j, pos))
        return c[len(sources) - 1]

    for k, op in enumerate(ops):
        if op != ca.OP_CONST:
            j += 1
        arg, res = f.instruction_input(k), f.instruction_output(k)
        if op == ca.OP_INPUT:
            work[res[0]] = ins[arg[0]].nz[arg[1]]
            constant.pop(res[0], None)
        elif op == ca.OP_OUTPUT:
            outs[res[0]][res[1]] = read(arg[0], 0)
        elif op == ca.OP_CONST and per_use:
            constant[res[0]] = k
        elif op == ca.OP_CONST:
            work[res[0]] = c[len(sources)]
            sources.append(k)
        elif len(arg) in (1, 2) and op not in (ca.OP_CALL, ca.OP_PARAMETER):
            operands = [read(a, pos) for pos, a in enumerate(arg)]
            work[res[0]] = (
                ca.SX.unary(op, *operands) if len(arg) == 1 else ca.SX.binary(op, *operands)
            )
            constant.pop(res[0], None)
        else:
            return None
    c = c[: len(sources)]
    out = [
        ca.SX(f.sparsity_out(i), ca.vertcat(*outs[i]) if outs[i] else ca.SX(0, 1))
        for i in range(f.n_out())
    ]
    fp = ca.Function(f"{f.name()}_p", [*ins, c], out, [*f.name_in(), "c"], f.name_out())
    return fp, sources, uses


def _reproduces(f: ca.Function, fp: ca.Function, const: np.ndarray) -> bool:
    """Whether ``fp(*args, const)`` equals ``f(*args)`` (to 1e-12 relative) at a generic point."""
    rng = np.random.default_rng(0)
    args = [rng.uniform(-0.5, 0.5, f.sparsity_in(i).shape) for i in range(f.n_in())]
    if fp.n_in() != f.n_in() + 1 or fp.nnz_in(f.n_in()) != const.size:
        return False
    for a, b in zip(
        f(*args) if f.n_out() > 1 else [f(*args)],
        fp(*args, const) if f.n_out() > 1 else [fp(*args, const)],
    ):
        va, vb = np.array(a, dtype=float), np.array(b, dtype=float)
        if not np.allclose(
            va, vb, rtol=1e-12, atol=1e-12 * max(1.0, float(np.max(np.abs(va), initial=0.0)))
        ):
            return False
    return True
