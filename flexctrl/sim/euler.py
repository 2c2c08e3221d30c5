"""Explicit (forward) Euler, the whole horizon run in compiled code like :mod:`.rk4`.

One step is ``x_next = x + h f(x, u(t))``: a CasADi Function ``(x, t, u, h) ->
(x_next, y_next)`` with one call of the model's forward dynamics, chained over
``chunk`` steps by ``mapaccum``, compiled to C and cached on disk by
:mod:`flexctrl.sim.compile` (or evaluated by CasADi's virtual machine), exactly
as the RK4 loop; only the step differs.

Stability
    Euler's amplification factor is ``R(z) = 1 + z``, ``z = lambda h``, so a
    step is stable for an eigenvalue ``lambda`` only where ``|1 + lambda h| <= 1``:
    a disc of radius 1 centred at -1, which touches the imaginary axis only at 0.
    An undamped mode (``lambda = +- i omega``) grows by ``|1 + i omega h| =
    sqrt(1 + (omega h)^2) > 1`` per step at *every* step, so Euler is never stable
    on an undamped flexible arm; the growth per step is ``(omega h)^2 / 2``, tiny
    at small steps, which is why short runs may look fine.  A mode with damping
    ratio ``zeta`` (``lambda = omega (-zeta +- i sqrt(1 - zeta^2))``) is stable
    for ``omega h <= 2 zeta``.  :class:`Euler` sets ``stability_limit = 0`` (the
    undamped limit) and its advice says so.  Measured limits, beside this theory:
    ``docs/stability.md``.
"""

from __future__ import annotations

import math
import os
from typing import ClassVar, Sequence

import casadi as ca
import numpy as np

from flexctrl.sim.base import output_function, try_expand
from flexctrl.sim.compile import DEFAULT_FLAGS, compile_function
from flexctrl.sim.rk4 import RK4


def euler_step_function(model, u_function: ca.Function | None = None) -> ca.Function:
    """``euler_step(x, t, u, h) -> (x_next, y_next)`` for ``model`` (y: see :func:`~flexctrl.sim.base.output_function`)."""
    f = try_expand(model.functions["f"])
    outputs = output_function(model)
    x = ca.MX.sym("x", model.n_x)
    t = ca.MX.sym("t")
    u = ca.MX.sym("u", model.n_u)
    h = ca.MX.sym("h")
    torque = u if u_function is None else u + ca.vec(u_function(t))
    x_next = x + h * f(x, torque)
    return ca.Function("euler_step", [x, t, u, h], [x_next, outputs(x_next)], ["x", "t", "u", "h"], ["x_next", "y_next"])


def euler_loop_function(step: ca.Function, n_steps: int) -> ca.Function:
    """``euler_loop(x0, T[1 x n], U[n_u x n], h) -> (X[n_x x n], Y[n_y x n])`` chaining ``step``."""
    acc = step.mapaccum(n_steps)
    x0 = ca.MX.sym("x0", step.size1_in(0))
    T = ca.MX.sym("T", 1, n_steps)
    U = ca.MX.sym("U", step.size1_in(2), n_steps)
    h = ca.MX.sym("h")
    X, Y = acc(x0, T, U, ca.repmat(h, 1, n_steps))
    return ca.Function(f"euler_loop{n_steps}", [x0, T, U, h], [X, Y], ["x0", "T", "U", "h"], ["X", "Y"])


class Euler(RK4):
    """Fixed-step explicit Euler over compiled chunks (see module docstring).

    Parameters
    ----------
    model, dt, u_function, chunk, energy_factor
        See :class:`~flexctrl.sim.base.Integrator`.
    compile, cache_dir, flags
        As for :class:`~flexctrl.sim.rk4.RK4`.
    expand
        Accepted for symmetry with :class:`~flexctrl.sim.rk4.RK4`; the Euler step
        calls ``f`` once, so there is nothing to expand.
    """

    name: ClassVar[str] = "euler"
    #: Largest stable ``omega * dt`` on the imaginary axis: none (undamped modes always grow).
    stability_limit: ClassVar[float] = 0.0

    def __init__(self, model, dt: float, *, u_function: ca.Function | None = None, chunk: int = 1000,
                 energy_factor: float = 100.0, compile: bool | None = None,
                 cache_dir: str | os.PathLike | None = None, flags: Sequence[str] = DEFAULT_FLAGS,
                 expand: bool = False):
        super().__init__(model, dt, u_function=u_function, chunk=chunk, energy_factor=energy_factor,
                         compile=compile, cache_dir=cache_dir, flags=flags, expand=expand)

    def _setup(self) -> None:
        loop = euler_loop_function(euler_step_function(self.model, self.u_function), self.chunk)
        self.compiled = compile_function(loop, enabled=self.compile, cache_dir=self.cache_dir, flags=self.flags)
        # Bound numpy buffers, as in RK4._setup (CasADi is column-major: an (rows x chunk) matrix is (chunk, rows) in C order).
        n = self.chunk
        self._args = [np.zeros(self.model.n_x), np.zeros(n), np.zeros((n, self.model.n_u)), np.array([self.dt])]
        self._res = [np.zeros((n, self.model.n_x)), np.zeros((n, loop.size1_out(1)))]
        self._buffer, self._evaluate = self.compiled.function.buffer()
        for i, a in enumerate(self._args):
            self._buffer.set_arg(i, memoryview(a))
        for i, r in enumerate(self._res):
            self._buffer.set_res(i, memoryview(r))

    def stability_advice(self, states=()) -> str:
        """Euler-specific advice: no step is stable on an undamped mode (see module docstring)."""
        w = float(self.model.omega_max)
        radii = [r for r in (self.jacobian_radius(x) for x in states) if math.isfinite(r)]
        w = max([w, *radii])
        return (f"Explicit Euler amplifies every undamped mode at every step (|1 + i omega dt| > 1); the fastest mode "
                f"here, omega = {w:.4g} rad/s, grows by about (omega dt)^2/2 = {0.5 * (w * self.dt) ** 2:.3g} per step "
                f"at dt = {self.dt:g} s. A mode with damping ratio zeta is stable only for omega dt <= 2 zeta. "
                "Use 'rk4' (stable for omega dt < 2.83), 'newmark' (unconditionally stable) or an implicit "
                "integrator ('idas', 'cvodes').")
