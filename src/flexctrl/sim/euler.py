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
    ``docs/explanation/numerical-stability.md``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from typing import ClassVar

import casadi as ca

from flexctrl.dynamics.parametric import try_expand
from flexctrl.sim.compile import DEFAULT_FLAGS
from flexctrl.sim.integrator import output_function
from flexctrl.sim.rk4 import RK4


def euler_step_function(model, u_function: ca.Function | None = None) -> ca.Function:
    """``euler_step(x, t, u, h) -> (x_next, y_next)`` for ``model``.

    ``y`` as :func:`~flexctrl.sim.integrator.output_function` gives it.

    Parameters
    ----------
    model : Model
        The arm; its ``f(x, u)`` gives the state derivative.
    u_function : casadi.Function, optional
        ``u(t)`` (N m) added to the step's ``u``.

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
    torque = u if u_function is None else u + ca.vec(u_function(t))
    x_next = x + h * f(x, torque)
    return ca.Function(
        "euler_step",
        [x, t, u, h],
        [x_next, outputs(x_next)],
        ["x", "t", "u", "h"],
        ["x_next", "y_next"],
    )


class Euler(RK4):
    """Fixed-step explicit Euler over compiled chunks (see module docstring).

    Parameters
    ----------
    model, dt, u_function, chunk, energy_factor
        See :class:`~flexctrl.sim.integrator.Integrator`.
    compile, cache_dir, flags
        As for :class:`~flexctrl.sim.rk4.RK4`.
    expand
        Accepted for symmetry with :class:`~flexctrl.sim.rk4.RK4`; the Euler step
        calls ``f`` once, so there is nothing to expand.
    """

    name: ClassVar[str] = "euler"
    #: Largest stable ``omega * dt`` on the imaginary axis: none (undamped modes always grow).
    stability_limit: float = 0.0

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
        super().__init__(
            model,
            dt,
            u_function=u_function,
            chunk=chunk,
            energy_factor=energy_factor,
            compile=compile,
            cache_dir=cache_dir,
            flags=flags,
            expand=expand,
        )

    def step_function(self) -> ca.Function:
        """The explicit Euler step, chained and compiled by :meth:`RK4._setup`."""
        return euler_step_function(self.model, self.u_function)

    def stability_advice(self, states=()) -> str:
        """Euler-specific advice: no step is stable on an undamped mode (see module docstring)."""
        w = float(self.model.omega_max)
        radii = [r for r in (self.jacobian_radius(x) for x in states) if math.isfinite(r)]
        w = max([w, *radii])
        return (
            "Explicit Euler amplifies every undamped mode at every step (|1 + i omega dt| > 1); "
            f"the fastest mode here, omega = {w:.4g} rad/s, grows by about (omega dt)^2/2 = "
            f"{0.5 * (w * self.dt) ** 2:.3g} per step at dt = {self.dt:g} s. A mode with damping "
            "ratio zeta is stable only for omega dt <= 2 zeta. Use 'rk4' (stable for omega dt < "
            "2.83), 'newmark' (unconditionally stable) or an implicit integrator ('idas', "
            "'cvodes')."
        )
