"""The plant's compiled step over one controller sample: RK4 substeps with the torque held."""

from __future__ import annotations

import re

import casadi as ca
import numpy as np

from flexctrl.dynamics.model import derived
from flexctrl.dynamics.parametric import parametric, try_expand
from flexctrl.sim.compile import compile_for, compile_function
from flexctrl.sim.integrator import output_function
from flexctrl.sim.rk4 import rk4_next, rk4_step_function

#: Above this many plant steps per controller sample the step function is a CasADi ``mapaccum`` loop
#: (compiles in constant time) instead of an unrolled chain (faster, but its C code grows with the
#: count).
UNROLL_LIMIT = 32


def plant_step_function(
    model, substeps: int, f: ca.Function | None = None, n_constants: int = 0
) -> ca.Function:
    """``advance(x, u, h[, c]) -> (X)``: ``substeps`` RK4 steps of ``h`` (s) with ``u`` held.

    ``X`` is (n_x, substeps).

    The steps are unrolled into one expression (compiled whole by :func:`advance_function`
    up to :data:`UNROLL_LIMIT` steps).  With ``f = fp(x, u, c)`` (the model's ``f`` with
    its constants as the input ``c`` of length ``n_constants``, from
    :func:`flexctrl.dynamics.parametric.constants_as_parameters`) the constants are an input
    too, and the Function's name depends only on the sizes: every configuration of one
    model shape then shares one compiled library.
    """
    x = ca.MX.sym("x", model.n_x)
    u = ca.MX.sym("u", model.n_u)
    h = ca.MX.sym("h")
    if f is None:
        step = rk4_step_function(model)
        advance = lambda xs, k: step(xs, k * h, u, h)[0]  # noqa: E731
        inputs, names, name = [x, u, h], ["x", "u", "h"], f"advance_{model.name}_{substeps}"
    else:
        c = ca.MX.sym("c", n_constants)

        def advance(xs, k):
            return rk4_next(lambda s: f(s, u, c), xs, h)

        inputs, names, name = (
            [x, u, h, c],
            ["x", "u", "h", "c"],
            f"advance_p_{model.n_x}_{model.n_u}_{n_constants}_{substeps}",
        )
    states = []
    current = x
    for k in range(substeps):
        current = advance(current, k)
        states.append(current)
    return ca.Function(_name(name), inputs, [ca.horzcat(*states)], names, ["X"])


def _name(text: str) -> str:
    return re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9]", "_", text)).strip("_")


def output_map(
    model, count: int, compile: bool | None = None, *, energies: bool = True
) -> ca.Function:
    """``Y = outputs(X)`` over ``count`` states (columns), compiled.

    The outputs are :func:`flexctrl.sim.integrator.output_function`'s: the rows of ``Y`` are
    the energies, tip and deflections (``energies=False``: the tip and deflections alone, a
    fraction of the cost).  Compiled with the model's constants as an input, one per use of
    a constant (one library per model shape, whatever the configuration:
    :func:`flexctrl.dynamics.parametric.constants_as_parameters`), and mapped with the
    model's constants; the compiled point Function is kept per model and rows, the map per
    count too.  Its values can differ from the virtual machine's in the last digits (fused
    multiply-adds), and the two row sets' tip and deflections from each other's likewise.
    """

    def build():
        single = _output_point(model, compile, energies)
        X = ca.MX.sym("X", model.n_x, count)
        return ca.Function(single.name(), [X], [single.map(count, "serial")(X)])

    return derived(model, ("output_map", count, compile, energies), build)


def _output_point(model, compile: bool | None, energies: bool) -> ca.Function:
    """The compiled outputs ``y(x)`` of one state, the model's constants embedded.

    Kept per model and rows.
    """

    def build():
        fun = output_function(model, energies)
        fp, constants = parametric(model, fun.name(), lambda: fun, per_use=True)
        if constants.size == 0:
            return compile_function(fun, enabled=compile).function
        # the constants embedded in a thin wrapper, then a plain map: a map with the constants as a
        # reduced input (``map(..., [1], [])``) is far slower to build for many columns and slower
        # to evaluate, for the same values bit for bit
        x = ca.MX.sym("x", model.n_x)
        compiled = compile_for(
            fp, "itself", lambda: fp, enabled=compile
        )  # every model of the structure
        return ca.Function(fun.name(), [x], [compiled.function(x, ca.DM(constants))])

    return derived(model, ("output_point", compile, energies), build)


def advance_function(model, substeps: int, compile: bool | None = None) -> tuple[ca.Function, bool]:
    """The plant's ``advance(x, u, h) -> (X)`` over one controller sample, and whether compiled.

    Up to :data:`UNROLL_LIMIT` steps: :func:`plant_step_function` compiled whole (the
    fastest per call).  Above (a fine plant step under a slow controller, e.g. ``amm:5``
    at 38 us under a 10 ms LQR: 260 steps): one compiled RK4 step, chained by a CasADi
    ``mapaccum`` loop in the virtual machine, so one library per model serves every step
    count and step size (a large model's single step compiles as slowly as a few unrolled
    ones).  Built once per model and step count (:func:`flexctrl.dynamics.model.derived`);
    the compiled Function is kept with the lifted ``f``
    (:func:`flexctrl.sim.compile.compile_for`), so a later configuration of the model shape
    wraps it with its own constants without building it again.
    """
    return derived(
        model, ("advance", substeps, compile), lambda: _advance_function(model, substeps, compile)
    )


def _advance_function(model, substeps: int, compile: bool | None) -> tuple[ca.Function, bool]:
    fp, constants = parametric(model, "f", lambda: model.functions["f"])
    x, u, h = ca.MX.sym("x", model.n_x), ca.MX.sym("u", model.n_u), ca.MX.sym("h")
    if substeps <= UNROLL_LIMIT:
        if constants.size == 0:  # f could not be rebuilt: one library per model
            compiled = compile_function(plant_step_function(model, substeps), enabled=compile)
            return compiled.function, compiled.compiled
        # kept with the lifted f: a later configuration of the model shape neither builds nor loads
        # it again
        compiled = compile_for(
            fp,
            ("advance", substeps),
            lambda: plant_step_function(model, substeps, fp, constants.size),
            enabled=compile,
        )
        X = compiled.function(x, u, h, ca.DM(constants))
    else:
        build = lambda: _single_step(model, fp, constants.size)  # noqa: E731
        # without constants the step reads the model's own f: one library per model, not per lift
        compiled = (
            compile_for(fp, "rk4_step", build, enabled=compile)
            if constants.size
            else compile_function(build(), enabled=compile)
        )
        # the constants enter once per step; as a constant of this (uncompiled) loop they are stored
        # once
        c: ca.DM | list = (
            ca.DM(np.tile(constants.reshape(-1, 1), (1, substeps))) if constants.size else []
        )
        X = compiled.function.mapaccum(substeps)(
            x,
            ca.repmat(u, 1, substeps),
            ca.repmat(h, 1, substeps),
            *([c] if constants.size else []),
        )
    return ca.Function(
        _name(f"advance_{model.name}_{substeps}"), [x, u, h], [X], ["x", "u", "h"], ["X"]
    ), compiled.compiled


def _single_step(model, fp: ca.Function, n_constants: int) -> ca.Function:
    """``rk4(x, u, h[, c]) -> x_next``: one RK4 step; with ``c`` named by the sizes alone.

    With the constants as the input ``c`` the generated code is the same for every
    configuration of one model shape, so one library serves them all.
    """
    x, u, h = ca.MX.sym("x", model.n_x), ca.MX.sym("u", model.n_u), ca.MX.sym("h")
    if n_constants == 0:
        f = try_expand(model.functions["f"])
        return ca.Function(
            _name(f"rk4x_{model.name}"),
            [x, u, h],
            [rk4_next(lambda s: f(s, u), x, h)],
            ["x", "u", "h"],
            ["x_next"],
        )
    c = ca.MX.sym("c", n_constants)
    return ca.Function(
        f"rk4x_p_{model.n_x}_{model.n_u}_{n_constants}",
        [x, u, h, c],
        [rk4_next(lambda s: fp(s, u, c), x, h)],
        ["x", "u", "h", "c"],
        ["x_next"],
    )
