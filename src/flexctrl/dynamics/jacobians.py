"""Exact Jacobians of a model's forward dynamics, the one Jacobian builder.

CasADi builds the derivative of a Function once per Function object: for a new model (a
new configuration or payload of a frozen-modes arm) the symbolic Jacobian of its ``f``
would be built from scratch, though the models of one structure differ only in the values
of their constants.  With ``shared=True`` the Jacobian is taken of ``f`` lifted with its
constants as an input (:func:`flexctrl.dynamics.parametric.parametric`, one constant per
use, so that coinciding values do not change the structure) and kept once per process for
each lifted structure (with the kept lift itself, and by its serialized form), so every
later model of that structure evaluates the kept Jacobian at its own constants.  The
operations are the same ones in the same order (the lift keeps them; the constants are
read from an input instead of the code), and the matrices are the same to the last bit
(``tests/dynamics/test_jacobians.py``).  A model whose ``f`` does not lift (it calls other
Functions, say) gets the per-model Jacobian.

The kept Jacobian of an SX lift (every assumed-modes model's) is built on an SX graph:
CasADi differentiates the expression itself, which is faster to build than the
derivative of an MX call of it.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from typing import Protocol, TypeVar

import casadi as ca
import numpy as np

from flexctrl.dynamics.parametric import FROM_LIFTED, Memo, parametric

#: Jacobians of lifted dynamics built in this process, by the lift's serialized form and the
#: outputs asked for.
SHARED = Memo(8)


#: A CasADi symbolic matrix.
Symbolic = TypeVar("Symbolic", ca.SX, ca.MX)


class DynamicsOwner(Protocol):
    """What the Jacobian builder reads of a model: ``functions["f"]``, ``n_x`` and ``n_u``."""

    @property
    def functions(self) -> Mapping[str, ca.Function]:
        """The model's Functions by name."""
        ...

    @property
    def n_x(self) -> int:
        """State dimension."""
        ...

    @property
    def n_u(self) -> int:
        """Input dimension."""
        ...


def jacobian_function(
    model: DynamicsOwner,
    *,
    value: bool = False,
    inputs: bool = False,
    outputs: ca.Function | None = None,
    shared: bool = False,
) -> ca.Function:
    """Exact Jacobians (CasADi AD) of ``xdot = f(x, u)`` as one MX Function of ``(x, u)``.

    The one Jacobian builder: linearisation (:class:`flexctrl.linear.Linearizer`, with
    ``shared=True``), stability advice
    (:meth:`flexctrl.sim.integrator.Integrator.jacobian_radius`) and the stability probe
    (:mod:`flexctrl.analysis.stability.probe`) all use it.
    Expanding it to SX (as the last two do) changes its values in the last digits, so
    each user keeps its choice.

    Parameters
    ----------
    model
        Anything with ``functions["f"]``, ``n_x`` and ``n_u``
        (a :class:`~flexctrl.dynamics.model.Model`).
    value
        Put ``f`` itself first.
    inputs
        Add ``B = df/du``.
    outputs
        A Function ``y(x, u)`` (sensors): add ``C = dy/dx`` and ``D = dy/du`` (never shared).
    shared
        Take ``f``'s part from the Jacobian kept for the model's lifted structure (see
        the module docstring); the values are the same.

    Returns
    -------
    casadi.Function
        ``(x, u) -> ([f,] A[, B][, C, D])``, in that order.
    """
    x = ca.MX.sym("x", model.n_x)
    u = ca.MX.sym("u", model.n_u)
    dynamics = _shared_dynamics(model, value, inputs) if shared else None
    if dynamics is not None:
        fp, constants = dynamics
        outs = list(fp(x, u, ca.DM(constants)))
    else:
        outs = _dynamics_jacobians(model.functions["f"], x, u, value, inputs)
    names = ["f"] * value + ["A"] + ["B"] * inputs
    if outputs is not None:
        y = outputs(x, u)
        outs += [ca.jacobian(y, x), ca.jacobian(y, u)]
        names += ["C", "D"]
    return ca.Function("jacobians", [x, u], outs, ["x", "u"], names)


def _dynamics_jacobians(
    f: ca.Function, x: Symbolic, u: Symbolic, value: bool, inputs: bool, *extra: Symbolic
) -> list[Symbolic]:
    """``[f,] A[, B]`` of ``f(x, u, *extra)``, as expressions of the symbols' type."""
    xdot = f(x, u, *extra)
    return [xdot] * value + [ca.jacobian(xdot, x)] + [ca.jacobian(xdot, u)] * inputs


def _shared_dynamics(
    model: DynamicsOwner, value: bool, inputs: bool
) -> tuple[ca.Function, np.ndarray] | None:
    """``(J(x, u, c), c)``: the kept Jacobian of the model's lifted ``f`` and its constants.

    None when ``f`` has no constants to lift.
    """
    # per use: a reduced model's constants coincide by value at some configurations, and a lift
    # per node would then give each configuration a structure (and a Jacobian) of its own
    lifted, constants = parametric(model, "f", lambda: model.functions["f"], per_use=True)
    if constants.size == 0:
        return None

    def build() -> ca.Function:
        if lifted.is_a("SXFunction"):  # differentiate the expression itself, not a call of it
            return _lifted_jacobians(ca.SX, lifted, model, constants.size, value, inputs)
        return _lifted_jacobians(ca.MX, lifted, model, constants.size, value, inputs)

    def by_content() -> ca.Function:
        """A lift made again (its kept object forgotten) finds it by its serialized form."""
        return SHARED.get(content_key(lifted, value, inputs), build)[0]

    # the lift kept for the structure is the same object for every model of it: no serializing
    return FROM_LIFTED.get(lifted, ("jacobians", value, inputs), by_content), constants


def _lifted_jacobians(
    symbol: type[Symbolic],
    lifted: ca.Function,
    model: DynamicsOwner,
    n_constants: int,
    value: bool,
    inputs: bool,
) -> ca.Function:
    """``jacobians_lifted(x, u, c)``: :func:`_dynamics_jacobians` of ``lifted`` on ``symbol``."""
    x, u = symbol.sym("x", model.n_x), symbol.sym("u", model.n_u)
    c = symbol.sym("c", n_constants)
    outs = _dynamics_jacobians(lifted, x, u, value, inputs, c)
    return ca.Function("jacobians_lifted", [x, u, c], outs)


def content_key(lifted: ca.Function, value: bool, inputs: bool) -> str:
    """The key of :data:`SHARED`: a hash of the lifted Function's form and the outputs asked for.

    Parameters
    ----------
    lifted : casadi.Function
        The lifted dynamics ``fp(x, u, c)``.
    value : bool
        Whether the Jacobian Function also returns ``f``.
    inputs : bool
        Whether it also returns the Jacobian with respect to the inputs.

    Returns
    -------
    str
        The key.
    """
    digest = hashlib.sha256(lifted.serialize().encode()).hexdigest()
    return f"{digest}|value={value}|inputs={inputs}"


__all__ = ["jacobian_function", "SHARED"]
