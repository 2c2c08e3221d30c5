"""The NMPC's shooting interval (RK4 over one sample, with sensitivities) and its horizon.

``F(x, u)``: ``substeps`` classical RK4 steps of the model's ``f(x, u)`` over one sample
(``f`` is called, not inlined, so generated code holds it once).  ``FJ(x, u)`` adds
``A = dx_next/dx`` and ``B = dx_next/du``:

``"midpoint"`` one Jacobian per interval at the RK4 node nearest its middle (after
              ``substeps // 2`` steps: the temporal middle for an even count), frozen over
              the interval (``Phi^substeps`` and ``(I + ... + Phi^(substeps-1)) Gam``): the
              midpoint rule, O(h^3) per interval where the start point is O(h^2), at half
              the Jacobians of ``"frozen"`` with 2 substeps.
``"exact"``   the Jacobian of ``f`` propagated through every RK4 stage (4 ``substeps``
              Jacobians per interval): the derivative of the nonlinear RK4 map.
``"frozen"``  the products over the interval's RK4 steps of the exact transition
              matrices of RK4 applied to the dynamics linearized at the start of a
              step, ``Phi = I + hJ + (hJ)^2/2 + (hJ)^3/6 + (hJ)^4/24`` and
              ``Gam = h (I + hJ/2 + (hJ)^2/6 + (hJ)^3/24) J_u``.  With
              ``jacobian_every = k`` one Jacobian serves ``k`` consecutive steps (the
              transition of the frozen linearization over them is ``Phi^k``, and
              ``(I + Phi + ... + Phi^(k-1)) Gam``).

Either way the shooting end ``x_next`` is the nonlinear RK4 map, so an RTI on inexact
sensitivities still has the fixed points of the nonlinear shooting equations.  Why a
Jacobian per RK4 step (or at the interval's middle) rather than one at the interval's
start: when the fastest elastic modes turn several times within a sample, the
linearization at the start misses the state's motion within the interval, and an RTI fed
on it diverges in saturated transients.

The horizon (:func:`symbolic_linearization`): the interval in scaled deviations, mapped over
the ``N`` intervals (or with one Jacobian per group of intervals,
:func:`grouped_sensitivities`), compiled once per model structure and found on disk by its
recipe (:func:`horizon_linearization`), kept in the process by content
(:func:`memoised`).
"""

from __future__ import annotations

import hashlib
import inspect
import math
import sys
from collections.abc import Callable
from pathlib import Path

import casadi as ca
import numpy as np

from flexctrl.dynamics import parametric
from flexctrl.dynamics.parametric import Memo
from flexctrl.dynamics.parametric import try_expand as _expanded
from flexctrl.sim import rk4
from flexctrl.sim.compile import compile_by_recipe, compile_function
from flexctrl.sim.rk4 import rk4_next

#: RK4 step bound ``|lambda|_max h`` used to choose the substeps (below the stability limit
#: 2.83 on the imaginary axis).
RK4_BOUND = 2.5


def auto_substeps(plant) -> int:
    """Fewest RK4 steps per sample with ``|lambda|_max h <= RK4_BOUND`` at the target.

    Parameters
    ----------
    plant : flexctrl.control.lqr.LinearPlant
        The linearization at the target (its continuous ``A``, 1/s) and the sample time.

    Returns
    -------
    int
        RK4 steps per sample, at least 1.
    """
    lam = float(np.max(np.abs(np.linalg.eigvals(np.asarray(plant.sys.A, dtype=float)))))
    return max(1, int(math.ceil(lam * plant.dt / RK4_BOUND)))


def _frozen_transition(Jx, Ju, h: float, steps: int, eye):
    """``(Phi^steps, (I + Phi + ... + Phi^(steps-1)) Gam)`` of RK4 on ``xdot = Jx x + Ju u``.

    ``h`` is the RK4 step (s).
    """
    hA = h * Jx
    hA2 = ca.mtimes(hA, hA)
    hA3 = ca.mtimes(hA2, hA)
    Phi = eye + hA + hA2 / 2 + hA3 / 6 + ca.mtimes(hA3, hA) / 24
    Gam = h * ca.mtimes(eye + hA / 2 + hA2 / 6 + hA3 / 24, Ju)
    Phi_k, Gam_k = Phi, Gam
    for _ in range(steps - 1):
        Phi_k, Gam_k = ca.mtimes(Phi, Phi_k), ca.mtimes(Phi, Gam_k) + Gam
    return Phi_k, Gam_k


def interval_core(
    f: ca.Function,
    nx: int,
    nu: int,
    dt: float,
    substeps: int,
    sensitivities: str | None,
    extra: tuple[ca.MX, ...] = (),
    jacobian_every: int = 1,
) -> tuple[ca.Function, ca.Function | None]:
    """``F(x, u, *extra)`` and ``FJ(x, u, *extra)`` of ``f(x, u, *extra)`` (module docstring).

    Parameters
    ----------
    f : casadi.Function
        ``f(x, u, *extra) -> xdot``.
    nx, nu : int
        Sizes of ``x`` and ``u``.
    dt : float
        The interval (one sample), s.
    substeps : int
        RK4 steps per interval.
    sensitivities : {"midpoint", "exact", "frozen"} or None
        How ``FJ`` differentiates; None builds ``F`` only (``FJ`` is None).
    extra : tuple of casadi.MX
        Symbols of further inputs of ``f`` (the model's lifted constants).
    jacobian_every : int
        RK4 steps per Jacobian of ``f`` (``"frozen"`` only).

    Returns
    -------
    F, FJ : casadi.Function
        ``F -> x_next`` and ``FJ -> (x_next, A, B)``.
    """
    if jacobian_every < 1:
        raise ValueError(
            f"jacobian_every = {jacobian_every} is not allowed; allowed: an integer >= 1"
        )
    x, u = ca.MX.sym("x", nx), ca.MX.sym("u", nu)
    names = ["x", "u"] + [f"p{i}" for i in range(len(extra))]
    h = dt / substeps
    rhs = lambda s: f(s, u, *extra)  # noqa: E731
    xf = x
    for _ in range(substeps):
        xf = rk4_next(rhs, xf, h)
    F = ca.Function("F", [x, u, *extra], [xf], names, ["x_next"])
    if sensitivities is None:
        return F, None
    xs, us = ca.SX.sym("x", nx), ca.SX.sym("u", nu)
    es = [ca.SX.sym(f"p{i}", e.sparsity()) for i, e in enumerate(extra)]
    fxu = f(xs, us, *es)
    fx = ca.Function(
        "f_jac", [xs, us, *es], [fxu, ca.jacobian(fxu, xs), ca.jacobian(fxu, us)], {"cse": True}
    )
    end = _propagate(sensitivities, lambda s: fx(s, u, *extra), rhs, x, nu, h, substeps)
    xe, Ad, Bd = end(jacobian_every)
    FJ = ca.Function("FJ", [x, u, *extra], [xe, Ad, Bd], names, ["x_next", "A", "B"])
    return F, FJ


def _propagate(sensitivities: str, fx, rhs, x, nu: int, h: float, substeps: int):
    """A function of ``jacobian_every`` giving ``(x_next, A, B)`` of the interval from ``x``.

    ``fx(x) -> (f, f_x, f_u)`` at the interval's input, ``rhs(x) -> f``.
    """
    nx = x.shape[0]
    eye = ca.DM.eye(nx)

    def frozen(jacobian_every: int):
        # one Jacobian at the start of a group of RK4 steps, frozen over the group
        xe, Ad, Bd = x, eye, ca.MX.zeros(nx, nu)
        done = 0
        while done < substeps:
            steps = min(jacobian_every, substeps - done)
            k1, Jx, Ju = fx(xe)
            Phi, Gam = _frozen_transition(Jx, Ju, h, steps, eye)
            Ad, Bd = ca.mtimes(Phi, Ad), ca.mtimes(Phi, Bd) + Gam
            xe = rk4_next(rhs, xe, h, k1=k1)
            for _ in range(steps - 1):
                xe = rk4_next(rhs, xe, h)
            done += steps
        return xe, Ad, Bd

    def midpoint(_every: int):
        # one Jacobian per interval, at the RK4 node nearest its middle, frozen over the interval
        xe, half = x, substeps // 2
        for _ in range(half):
            xe = rk4_next(rhs, xe, h)
        k1, Jx, Ju = fx(xe)
        Ad, Bd = _frozen_transition(Jx, Ju, h, substeps, eye)
        xe = rk4_next(rhs, xe, h, k1=k1)
        for _ in range(substeps - half - 1):
            xe = rk4_next(rhs, xe, h)
        return xe, Ad, Bd

    def exact(_every: int):
        # RK4 on (x, A, B): d/dt (x, A, B) = (f, f_x A, f_x B + f_u)
        def with_sensitivities(state):
            xs, A, B = state
            k, Jx, Ju = fx(xs)
            return k, ca.mtimes(Jx, A), ca.mtimes(Jx, B) + Ju

        state = (x, eye, ca.MX.zeros(nx, nu))
        for _ in range(substeps):
            state = rk4_next(with_sensitivities, state, h)
        return state

    return {"frozen": frozen, "midpoint": midpoint}.get(sensitivities, exact)


def interval_functions(
    model, dt: float, substeps: int, sensitivities: str | None, jacobian_every: int = 1
) -> tuple[ca.Function, ca.Function | None]:
    """``F(x, u) -> x_next`` and ``FJ(x, u) -> (x_next, A, B)`` of ``model`` over one sample.

    Physical units; ``F`` is ``substeps`` classical RK4 steps of the model's ``f``, ``FJ``
    adds the sensitivities ``A = dx_next/dx``, ``B = dx_next/du`` (module docstring).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        Its ``f(x, u)``.
    dt, substeps, sensitivities, jacobian_every
        As for :func:`interval_core` (``dt`` in s).

    Returns
    -------
    F, FJ : casadi.Function
        ``FJ`` is None without sensitivities.
    """
    f = _expanded(model.functions["f"])
    return interval_core(
        f, model.n_x, model.n_u, dt, substeps, sensitivities, jacobian_every=jacobian_every
    )


def group_centres(N: int, stages: int) -> list[int]:
    """The interval whose Jacobian serves each group of ``stages`` consecutive intervals.

    The middle one of each group (the earlier of two middles), the last group shorter when
    ``stages`` does not divide ``N``.

    Parameters
    ----------
    N : int
        Intervals of the horizon.
    stages : int
        Intervals per group.

    Returns
    -------
    list of int
    """
    return [j + (min(stages, N - j) - 1) // 2 for j in range(0, N, stages)]


def grouped_sensitivities(
    shoot: ca.Function, lin: ca.Function, n: int, m: int, N: int, stages: int
) -> ca.Function:
    """``(Z, V, p) -> (F, A, B)`` over ``N`` intervals with one ``(A, B)`` per ``stages`` of them.

    ``shoot(z, v, p) -> F`` gives every interval's nonlinear shooting end; ``lin(z, v, p) ->
    (F, A, B)`` is evaluated only at :func:`group_centres` and its ``(A, B)`` held over the
    group: the RTI keeps the fixed points of the nonlinear shooting equations (the ends
    are exact), with sensitivities frozen along the horizon for ``stages`` samples.  The
    outputs have the layout of ``lin.map(N)``, so the QP assembly is unchanged.

    Parameters
    ----------
    shoot, lin : casadi.Function
        ``shoot(z, v, p) -> F`` and ``lin(z, v, p) -> (F, A, B)``.
    n, m, N, stages : int
        States, inputs, intervals, and intervals per Jacobian.

    Returns
    -------
    casadi.Function
    """
    centres = group_centres(N, stages)
    Z, V, p = ca.MX.sym("Z", n, N), ca.MX.sym("V", m, N), ca.MX.sym("p", lin.sparsity_in(2))
    F = shoot.map("nmpc_shoot_map", "serial", N, [2], [])(Z, V, p)
    _, Ac, Bc = lin.map("nmpc_centres_map", "serial", len(centres), [2], [])(
        Z[:, centres], V[:, centres], p
    )
    A, B = [], []
    for g, j in enumerate(range(0, N, stages)):
        for _ in range(min(stages, N - j)):
            A.append(Ac[:, g * n : (g + 1) * n])
            B.append(Bc[:, g * m : (g + 1) * m])
    return ca.Function(
        linearization_name(N, stages), [Z, V, p], [F, ca.horzcat(*A), ca.horzcat(*B)]
    )


def linearization_name(N: int, stages: int) -> str:
    """The name of the horizon linearization's Function (and of its library's symbol).

    Parameters
    ----------
    N, stages : int
        Intervals, and intervals per Jacobian.

    Returns
    -------
    str
    """
    return f"nmpc_linearize_{N}_by_{stages}" if stages > 1 else f"nmpc_linearize_{N}"


def symbolic_linearization(
    fp: ca.Function,
    nc: int,
    n: int,
    m: int,
    N: int,
    dt: float,
    substeps: int,
    settings,
) -> ca.Function:
    """``linmap(Z, V, p) -> (F, A, B)``: the scaled shooting intervals over the horizon.

    Parameters
    ----------
    fp : casadi.Function
        The model's ``f`` with its ``nc`` constants lifted to an input, ``fp(x, u, c)``
        (``fp(x, u)`` when ``nc = 0``).
    nc : int
        Number of lifted constants.
    n, m, N : int
        States, inputs and intervals of the horizon.
    dt : float
        The sample, s.
    substeps : int
        RK4 steps per sample.
    settings : flexctrl.spec.mpc_settings.NMPCSettings
        Its ``sensitivities``, ``jacobian_every`` and ``stages_per_jacobian``.

    Returns
    -------
    casadi.Function
        ``linmap`` with ``Z`` (n x N), ``V`` (m x N) and ``p = (x_op, u_op, S_x, S_u, c)``;
        ``F`` (n x N), ``A`` (n x nN), ``B`` (n x mN) in scaled deviations.
    """
    extra = (ca.MX.sym("c", nc),) if nc else ()
    Fp, FJp = interval_core(
        fp if nc else _expanded(fp),
        n,
        m,
        dt,
        substeps,
        settings.sensitivities,
        extra,
        settings.jacobian_every,
    )
    if FJp is None:
        raise ValueError(
            "the horizon's linearization needs sensitivities; allowed: "
            "'midpoint', 'exact', 'frozen'"
        )
    p = ca.MX.sym("p", 2 * n + 2 * m + nc)
    xop, uop = p[:n], p[n : n + m]
    Sx, Su = p[n + m : 2 * n + m], p[2 * n + m : 2 * n + 2 * m]
    z, v = ca.MX.sym("z", n), ca.MX.sym("v", m)
    consts = (p[2 * n + 2 * m :],) if nc else ()
    xn, Ad, Bd = FJp(xop + Sx * z, uop + Su * v, *consts)
    Fs = (xn - xop) / Sx
    As = Ad * ca.repmat(Sx.T, n, 1) / ca.repmat(Sx, 1, n)
    Bs = Bd * ca.repmat(Su.T, n, 1) / ca.repmat(Sx, 1, m)
    lin = ca.Function("nmpc_interval", [z, v, p], [Fs, As, Bs], ["z", "v", "p"], ["F", "A", "B"])
    if settings.stages_per_jacobian > 1:
        shoot = ca.Function(
            "nmpc_shoot", [z, v, p], [(Fp(xop + Sx * z, uop + Su * v, *consts) - xop) / Sx]
        )
        return grouped_sensitivities(shoot, lin, n, m, N, settings.stages_per_jacobian)
    return lin.map(linearization_name(N, 1), "serial", N, [2], [])


def _source_digest() -> str:
    digest = hashlib.sha256()
    for module in (sys.modules[__name__], rk4, parametric):
        digest.update(Path(inspect.getfile(module)).read_bytes())
    return digest.hexdigest()


#: The digest of the source this process imported (read once, at import: an edit to the files
#: during a long study must not name a library built by the code already loaded).
_BUILDER_SOURCE_DIGEST = _source_digest()


def builder_source_digest() -> str:
    """SHA-256 of the source of the modules that build the linearization from ``fp``, as imported.

    This module (interval, grouping, the horizon), the RK4 step and the lift's ``try_expand``:
    part of the recipe a library is found by, so an edit to any of them builds anew.
    """
    return _BUILDER_SOURCE_DIGEST


def horizon_linearization(
    fp: ca.Function,
    nc: int,
    n: int,
    m: int,
    N: int,
    dt: float,
    substeps: int,
    settings,
    recipe: str | None = None,
    check: Callable[[ca.Function], bool] | None = None,
) -> tuple:
    """:func:`symbolic_linearization`, compiled to C when ``settings.compile``.

    The library comes from the disk cache when its code was built before.  With ``recipe``
    (a key naming ``fp``, the sizes and the settings: the caller's memo key) the library is
    looked up by the recipe and :func:`builder_source_digest` before anything is built, so a
    worker whose cache holds it skips the symbolic construction and the serialization that
    finds a library by its content.  A library found by its recipe must pass ``check`` (the
    caller's comparison with the model at a generic point); one that fails is removed, with a
    warning, and built again.

    Parameters
    ----------
    fp, nc, n, m, N, dt, substeps
        As for :func:`symbolic_linearization`.
    settings : flexctrl.spec.mpc_settings.NMPCSettings
        Its ``compile``, ``sensitivities``, ``jacobian_every`` and ``stages_per_jacobian``.
    recipe : str, optional
        The key the library is found by before it is built.
    check : callable, optional
        ``check(linmap) -> bool``: whether a library found by its recipe is the right one.

    Returns
    -------
    tuple
        ``(linmap, compiled, compile_seconds, cache_hit)``: the Function, whether it is a
        compiled library, the compiler's time (s) and whether the library was on disk.
    """
    build = lambda: symbolic_linearization(fp, nc, n, m, N, dt, substeps, settings)  # noqa: E731
    if not settings.compile:
        return build(), False, 0.0, False
    if recipe is None:
        result = compile_function(build())
    else:
        result = compile_by_recipe(
            linearization_name(N, settings.stages_per_jacobian),
            f"{recipe}\0{builder_source_digest()}",
            build,
            check=check,
        )
    return result.function, result.compiled, result.compile_seconds, result.cache_hit


#: Horizon linearizations built in this process, by :func:`flexctrl.sim.compile.content_key`
#: (the least recently used dropped beyond ``MEMO_SIZE``).
MEMO_SIZE = 8
_BUILT = Memo(MEMO_SIZE)


def memoised(key: str, build: Callable[[], tuple]) -> tuple:
    """``build()``'s tuple plus ``reused`` (bool): built once per process for each content ``key``.

    For what is a pure function of its key's content: the NMPC's compiled horizon
    linearization depends only on the lifted ``f`` (its serialized form, constants as an
    input), the Jacobian recipe and the sizes, so the Functions built for one
    configuration serve every other of the same model structure (the symbolic Jacobian
    with common subexpressions and the serialization that finds the library on disk are
    paid once per worker).  The built Functions hold no state between calls; each
    controller keeps its own QP solver.

    Parameters
    ----------
    key : str
        :func:`flexctrl.sim.compile.content_key` of what ``build`` depends on.
    build : callable
        ``build() -> tuple``, e.g. :func:`horizon_linearization`'s.

    Returns
    -------
    tuple
        ``(*build(), reused)``.
    """
    value, reused = _BUILT.get(key, build)
    return (*value, reused)


__all__ = [
    "interval_core",
    "interval_functions",
    "auto_substeps",
    "RK4_BOUND",
    "memoised",
    "group_centres",
    "grouped_sensitivities",
    "horizon_linearization",
    "symbolic_linearization",
    "linearization_name",
    "builder_source_digest",
]
