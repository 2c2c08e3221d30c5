"""Classical fixed-step Runge-Kutta (RK4), the whole horizon run in compiled code.

One step is a CasADi Function ``(x, t, u, h) -> (x_next, y_next)`` that calls the
model's forward dynamics four times (kept as calls, so the generated C holds ``f``
once and compiles quickly) and evaluates the outputs (energies, tip, deflections)
at the new state.  ``mapaccum`` chains ``chunk`` steps (1000 by default) into one
Function; it is compiled to C and cached on disk by :mod:`flexctrl.sim.compile`,
or evaluated by CasADi's virtual machine when compilation is off or impossible.
The step ``h`` is an input, so one library serves every dt; the last chunk of a
horizon that is not a whole number of chunks is padded and the padding dropped.

Stability and numerical damping
    RK4's amplification factor on an undamped mode is ``R(i y)``, ``y = omega h``,
    with ``|R(iy)|^2 = 1 - y^6/72 + y^8/576``: stable up to ``y = 2 sqrt(2) = 2.83``
    on the imaginary axis (advice uses 2.785, the real-axis limit, to be safe).
    Below the limit RK4 does not conserve energy: a mode keeps the fraction
    ``|R|^2`` of its energy per step, which is 1 - 2e-8 at y = 0.1 but 0.81 at
    y = 1.65 and 0.52 at y = 2.05.  High modes are therefore damped out
    numerically while low ones are kept almost exactly.

    On the arm an initial deflection puts energy into the fast modes of the free-joint
    Jacobian; at steps near the limit RK4 damps it away while the slow modes (the
    frequencies the studies look at) are kept, and the energy is conserved to round-off
    only at steps well below the limit (``tests/sim/test_integrators_on_the_arm.py``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from flexctrl.dynamics.parametric import try_expand
from flexctrl.sim.bound import bind_buffer
from flexctrl.sim.compile import DEFAULT_FLAGS, CompiledFunction, compile_function
from flexctrl.sim.integrator import Integrator, output_function


def _axpy(x, a, k):
    """``x + a * k``, entry by entry for tuples (an augmented state)."""
    if isinstance(x, tuple):
        return tuple(_axpy(xi, a, ki) for xi, ki in zip(x, k))
    return x + a * k


def _rk4_combine(x, h, k1, k2, k3, k4):
    """``x + (h / 6) (k1 + 2 k2 + 2 k3 + k4)``, entry by entry for tuples."""
    if isinstance(x, tuple):
        return tuple(_rk4_combine(xi, h, a, b, c, d) for xi, a, b, c, d in zip(x, k1, k2, k3, k4))
    return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def rk4_next(f: Callable, x, h, t=None, *, k1=None):
    """The state after one classical RK4 step of length ``h`` of ``xdot = f(x)`` (or ``f(x, t)``).

    The one place RK4's stages are written; symbolic (CasADi) or numeric.  The
    expression is, in this order of floating-point operations,
    ``k2 = f(x + (0.5 h) k1)``, ``k3 = f(x + (0.5 h) k2)``, ``k4 = f(x + h k3)``,
    ``x + (h / 6) (((k1 + 2 k2) + 2 k3) + k4)``, with the stage times ``t``,
    ``t + 0.5 h``, ``t + 0.5 h``, ``t + h``.

    Parameters
    ----------
    f
        The right-hand side: a callable of the state (and time), e.g.
        ``lambda s: fun(s, u, c)`` for a CasADi Function with torques and parameters.
    x
        The state, or a tuple of states (an augmented system such as a state with its
        sensitivities: ``f`` then returns a tuple of the same length).
    h
        Step (s): a number or a symbol.
    t
        Time at ``x``; None when ``f`` does not take one.
    k1
        ``f(x)`` already evaluated (e.g. together with its Jacobian).
    """
    if t is None:
        k1 = f(x) if k1 is None else k1
        k2 = f(_axpy(x, 0.5 * h, k1))
        k3 = f(_axpy(x, 0.5 * h, k2))
        k4 = f(_axpy(x, h, k3))
    else:
        k1 = f(x, t) if k1 is None else k1
        k2 = f(_axpy(x, 0.5 * h, k1), t + 0.5 * h)
        k3 = f(_axpy(x, 0.5 * h, k2), t + 0.5 * h)
        k4 = f(_axpy(x, h, k3), t + h)
    return _rk4_combine(x, h, k1, k2, k3, k4)


def rk4_step_function(
    model, u_function: ca.Function | None = None, *, expand: bool = False
) -> ca.Function:
    """``rk4_step(x, t, u, h) -> (x_next, y_next)`` of ``model``; ``y``: :func:`output_function`.

    Parameters
    ----------
    model : Model
        The arm; its ``f(x, u)`` gives the state derivative.
    u_function : casadi.Function, optional
        ``u(t)`` (N m) added to the step's ``u``; none by default.
    expand : bool
        Expand the step into one SX expression.

    Returns
    -------
    casadi.Function
        The step; ``t`` and ``h`` in s.
    """
    f = try_expand(model.functions["f"])
    outputs = output_function(model)
    x = ca.MX.sym("x", model.n_x)
    t = ca.MX.sym("t")
    u = ca.MX.sym("u", model.n_u)
    h = ca.MX.sym("h")

    def rhs(xs, ts):
        torque = u if u_function is None else u + ca.vec(u_function(ts))
        return f(xs, torque)

    x_next = rk4_next(rhs, x, h, t)
    step = ca.Function(
        "rk4_step",
        [x, t, u, h],
        [x_next, outputs(x_next)],
        ["x", "t", "u", "h"],
        ["x_next", "y_next"],
    )
    return step.expand() if expand else step


def loop_function(step: ca.Function, n_steps: int, name: str = "rk4_loop") -> ca.Function:
    """``loop(x0, T[1 x n], U[n_u x n], h) -> (X[n_x x n], Y[n_y x n])``: ``n`` steps chained.

    Parameters
    ----------
    step : casadi.Function
        Any one-step map ``step(x, t, u, h) -> (x_next, y_next)``; ``t`` and ``h`` in s.
    n_steps : int
        Number of steps ``n`` chained.
    name : str
        Prefix of the Function's name (``n`` is appended).

    Returns
    -------
    casadi.Function
        The chained loop.
    """
    acc = step.mapaccum(n_steps)
    x0 = ca.MX.sym("x0", step.size1_in(0))
    T = ca.MX.sym("T", 1, n_steps)
    U = ca.MX.sym("U", step.size1_in(2), n_steps)
    h = ca.MX.sym("h")
    X, Y = acc(x0, T, U, ca.repmat(h, 1, n_steps))
    return ca.Function(f"{name}{n_steps}", [x0, T, U, h], [X, Y], ["x0", "T", "U", "h"], ["X", "Y"])


def rk4_loop_function(step: ca.Function, n_steps: int) -> ca.Function:
    """``rk4_loop(x0, T[1 x n], U[n_u x n], h) -> (X[n_x x n], Y[n_y x n])`` chaining ``step``.

    Parameters
    ----------
    step : casadi.Function
        The RK4 step of :func:`rk4_step_function`.
    n_steps : int
        Number of steps chained.

    Returns
    -------
    casadi.Function
        :func:`loop_function` named ``rk4_loop<n_steps>``.
    """
    return loop_function(step, n_steps, "rk4_loop")


def held_sample_loop(
    model, h: float, substeps: int, chunk: int, name: str = "held_rk4"
) -> ca.Function:
    """``loop(x0, U[n_u x chunk]) -> X[n_x x chunk]``: ``substeps`` RK4 steps of ``h`` per sample.

    The torque is held over a sample.  The sample-level building block of the FEM timing report
    and the speed/accuracy study: the output is the state at the end of each of ``chunk`` samples.

    Parameters
    ----------
    model : Model
        The arm; its ``f(x, u)`` gives the state derivative.
    h : float
        RK4 step (s).
    substeps : int
        RK4 steps per sample.
    chunk : int
        Samples per call.
    name : str
        Name of the Function.

    Returns
    -------
    casadi.Function
        ``loop(x0, U) -> X``; ``U`` in N m.
    """
    f = model.functions["f"]
    x, u = ca.MX.sym("x", model.n_x), ca.MX.sym("u", model.n_u)
    step = ca.Function("rk4", [x, u], [rk4_next(lambda s: f(s, u), x, h)])
    xs = ca.MX.sym("x", model.n_x)
    sample = ca.Function(
        "sample", [xs, u], [step.mapaccum(substeps)(xs, ca.repmat(u, 1, substeps))[:, -1]]
    )
    loop = sample.mapaccum(chunk)
    args = loop.mx_in()
    return ca.Function(name, args, loop.call(args))


#: The largest ``omega * h`` at which RK4 is offered as stable: the real-axis limit 2.785 (the
#: imaginary-axis limit is 2 sqrt 2 = 2.828; :mod:`flexctrl.analysis.stability.theory` computes both
#: from the polynomial).  The one copy.
RK4_STABILITY_LIMIT = 2.785

#: Share of :data:`RK4_STABILITY_LIMIT` a step chosen by :func:`rk4_step` may use.
RK4_MARGIN = 0.9


def rk4_step(omega_max: float, scene_dt: float, margin: float = RK4_MARGIN) -> float:
    """The scene's step divided by the smallest whole number that makes RK4 stable (s).

    ``omega_max * dt <= margin * RK4_STABILITY_LIMIT``; the scene's step itself when it already is.

    Parameters
    ----------
    omega_max : float
        Largest natural frequency of the model (rad/s); a value <= 0 keeps the scene's step.
    scene_dt : float
        The scene's sample time (s).
    margin : float
        Share of :data:`RK4_STABILITY_LIMIT` the step may use.

    Returns
    -------
    float
        The step (s), ``scene_dt / k`` for a whole ``k >= 1``.
    """
    if omega_max <= 0:
        return scene_dt
    k = max(1, math.ceil(scene_dt * omega_max / (margin * RK4_STABILITY_LIMIT) - 1e-12))
    return scene_dt / k


class RK4(Integrator):
    """Fixed-step RK4 over compiled chunks (see module docstring).

    Parameters
    ----------
    model, dt, u_function, chunk, energy_factor
        See :class:`~flexctrl.sim.integrator.Integrator`.
    compile : bool or None
        ``False``: CasADi virtual machine; ``None`` (default): compile unless
        ``FLEXCTRL_NO_COMPILE`` is set; ``True``: compile (falls back with a
        warning when it cannot).
    cache_dir : path, optional
        Library cache (default :func:`flexctrl.user_cache.cache_directory`).
    flags : sequence of str
        C compiler flags.
    expand : bool
        Expand the step into one SX expression (larger code, sometimes faster in
        the virtual machine).
    """

    name: ClassVar[str] = "rk4"
    stability_limit: float = RK4_STABILITY_LIMIT

    def __init__(
        self,
        model,
        dt: float,
        *,
        u_function: ca.Function | None = None,
        chunk: int = 1000,
        energy_factor: float = 100.0,
        compile: bool | None = None,
        cache_dir: str | os.PathLike | None = None,
        flags: Sequence[str] = DEFAULT_FLAGS,
        expand: bool = False,
    ):
        super().__init__(model, dt, u_function=u_function, chunk=chunk, energy_factor=energy_factor)
        self.compile = compile
        self.cache_dir = cache_dir
        self.flags = tuple(flags)
        self.expand = expand
        self.compiled: CompiledFunction | None = None

    def settings(self) -> dict[str, Any]:
        """Integrator settings plus how the loop is evaluated."""
        out = super().settings()
        c = self.compiled
        out.update(
            {
                "compiled": bool(c and c.compiled),
                "cache_hit": bool(c and c.cache_hit),
                "compile_time_s": c.compile_seconds if c else 0.0,
                "library": str(c.path) if c and c.path else None,
                "flags": list(c.flags) if c and c.compiled else [],
                "vm_reason": c.reason if c else "",
            }
        )
        return out

    def step_function(self) -> ca.Function:
        """The one-step map ``step(x, t, u, h) -> (x_next, y_next)`` chained by :meth:`_setup`."""
        return rk4_step_function(self.model, self.u_function, expand=self.expand)

    def _setup(self) -> None:
        loop = loop_function(self.step_function(), self.chunk, f"{self.name}_loop")
        self.compiled = compile_function(
            loop, enabled=self.compile, cache_dir=self.cache_dir, flags=self.flags
        )
        # Evaluate through a CasADi FunctionBuffer bound to numpy arrays: no DM conversions per
        # chunk.  CasADi is column-major, so an (n_rows x chunk) matrix is a C-ordered (chunk,
        # n_rows) array.
        n = self.chunk
        self._args = [
            np.zeros(self.model.n_x),
            np.zeros(n),
            np.zeros((n, self.model.n_u)),
            np.array([self.dt]),
        ]
        self._res = [np.zeros((n, self.model.n_x)), np.zeros((n, loop.size1_out(1)))]
        self._buffer, self._evaluate = self.compiled.function.buffer()
        bind_buffer(self._buffer, self._args, self._res)

    def _advance(
        self, x0: np.ndarray, times: np.ndarray, U: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        k = U.shape[0]
        x_arg, t_arg, u_arg, _h = self._args
        x_arg[:] = x0
        t_arg[:k] = times[:k]
        u_arg[:k] = U
        if k < self.chunk:  # pad the last chunk; the extra steps are dropped
            t_arg[k:] = times[k - 1] + self.dt * np.arange(1, self.chunk - k + 1)
            u_arg[k:] = U[-1]
        self._evaluate()
        return self._res[0][:k].copy(), self._res[1][:k].copy()
