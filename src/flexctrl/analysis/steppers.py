"""Steppers and drivers: every simulation method advanced through one interface, on one output
grid, open loop or with a controller (see :mod:`flexctrl.analysis.accuracy`)."""

from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flexctrl.analysis.simulation_methods import DIVERGED, OUTPUT_DT, RK4_SAFETY, Method
from flexctrl.errors import SimulationError, SpecError

# -- steppers ------------------------------------------------------------------------------


class Stepper:
    """Advance a model over output samples with a held torque (see the module docstring).

    Attributes
    ----------
    model : flexctrl.dynamics.model.Model
    method : Method
    dt : float
        Output sample interval (s).
    setup_s : float
        Build and compile time (s), not counted in the run's wall time.
    step_s : float
        The integrator's step (s); for adaptive methods the tolerance-driven mean step
        of the last run.
    """

    def __init__(self, model, method: Method, dt: float = OUTPUT_DT):
        self.model, self.method, self.dt = model, method, float(dt)
        self.setup_s = 0.0
        self.step_s = math.nan
        self.counters: dict[str, float] = {}

    def advance(self, x: np.ndarray, u: np.ndarray, t0: float, n: int) -> np.ndarray:
        """States after each of ``n`` output samples from ``x`` at ``t0`` with torque ``u`` held,
        shape (n, n_x)."""
        raise NotImplementedError

    def reset(self) -> None:
        """Clear per-run counters."""
        self.counters = {}


def stable_substeps(model, dt: float, safety: float = RK4_SAFETY) -> int:
    """RK4 steps per output sample ``dt`` so that ``omega h <= safety`` (omega: the larger of
    ``Model.omega_max`` and the free-joint spectral radius at the reference configuration)."""
    from flexctrl.dynamics.fem.locked_spectrum import rk4_step_for

    return rk4_step_for(model, dt, safety)


class RK4Stepper(Stepper):
    """RK4 with ``substeps`` steps per output sample, ``chunk`` samples per compiled call."""

    def __init__(
        self,
        model,
        method: Method,
        dt: float = OUTPUT_DT,
        *,
        chunk: int = 10,
        compile: bool | None = None,
    ):
        super().__init__(model, method, dt)
        from flexctrl.sim.compile import compile_function
        from flexctrl.sim.rk4 import held_sample_loop

        start = time.perf_counter()
        if method.step is None:
            substeps = stable_substeps(model, dt) * method.divide
        else:
            substeps = max(1, int(round(dt / method.step)))
            if abs(substeps * method.step - dt) > 1e-9 * dt:
                raise SpecError(
                    f"method '{method.label}': step {method.step:g} s does not divide the output "
                    f"sample {dt:g} s; "
                    "allowed: dt / step a whole number",
                    key="method",
                )
        self.substeps, self.chunk = substeps, chunk
        h = dt / substeps
        name = re.sub(r"[^A-Za-z0-9]+", "_", f"acc_{model.name}_{substeps}x{chunk}").strip("_")
        loop = held_sample_loop(model, h, substeps, chunk, name=name)
        compiled = compile_function(loop, enabled=compile)
        self._fun = compiled.function
        self.compiled = compiled.compiled
        self.step_s = h
        self.setup_s = time.perf_counter() - start

    def advance(self, x: np.ndarray, u: np.ndarray, t0: float, n: int) -> np.ndarray:
        out = np.empty((n, x.size))
        U = np.tile(np.asarray(u, dtype=float).reshape(-1, 1), (1, self.chunk))
        for s in range(0, n, self.chunk):
            k = min(self.chunk, n - s)
            block = np.asarray(self._fun(x, U), dtype=float).T
            out[s : s + k] = block[:k]
            x = block[k - 1]
            if not np.all(np.isfinite(x)) or np.max(np.abs(x)) > DIVERGED:
                raise SimulationError(
                    f"RK4 ({self.method.label}, h = {self.step_s:.3g} s) diverged by t = "
                    f"{t0 + (s + k) * self.dt:.4g} s: "
                    f"omega_max h = {float(self.model.omega_max) * self.step_s:.3g}; RK4 is "
                    "stable for omega h < 2.83"
                )
        self.counters["steps"] = self.counters.get("steps", 0) + n * self.substeps
        return out


class SundialsStepper(Stepper):
    """CVODES, IDAS or solve_ivp through the package's integrators (their ``_advance``)."""

    def __init__(self, model, method: Method, dt: float = OUTPUT_DT):
        super().__init__(model, method, dt)
        from flexctrl.sim import get_integrator

        start = time.perf_counter()
        options: dict[str, Any] = {"rtol": method.rtol, "atol": method.atol}
        if method.integrator == "scipy":
            options["method"] = method.variant
        self._integrator = get_integrator(method.integrator)(model, dt, **options).setup()
        self.setup_s = time.perf_counter() - start

    def reset(self) -> None:
        super().reset()
        self._integrator.counters = {}

    def advance(self, x: np.ndarray, u: np.ndarray, t0: float, n: int) -> np.ndarray:
        times = t0 + self.dt * np.arange(n + 1)
        U = np.tile(np.asarray(u, dtype=float), (n, 1))
        X, _ = self._integrator._advance(np.asarray(x, dtype=float).copy(), times, U)
        X = np.asarray(X, dtype=float).reshape(n, -1)
        if not np.all(np.isfinite(X)) or np.max(np.abs(X)) > DIVERGED:
            raise SimulationError(
                f"{self.method.label} produced non-finite states between t = {t0:.4g} s and "
                f"{times[-1]:.4g} s"
            )
        self.counters = dict(self._integrator.counters)
        return X


class NewmarkStepper(Stepper):
    """Trapezoidal Newmark (:func:`flexctrl.dynamics.fem.newmark_dae.simulate`), restarted at every
    torque change.

    Each call starts from consistent accelerations at its first instant (the torque
    jumps there), which is what a held torque means.
    """

    def __init__(self, model, method: Method, dt: float = OUTPUT_DT):
        super().__init__(model, method, dt)
        from flexctrl.dynamics.fem.newmark import model_dae_problem

        start = time.perf_counter()
        self._u = np.zeros(model.n_u)
        self._problem = model_dae_problem(model, lambda t: self._u, tangent="potential")
        step = method.step
        if step is None:
            raise SpecError(
                f"method '{method.label}': newmark needs a step; allowed: 'newmark@STEP', "
                "e.g. 'fem:4/newmark@1ms'",
                key="method",
            )
        self.ratio = max(1, int(round(dt / step)))
        if abs(self.ratio * step - dt) > 1e-9 * dt:
            raise SpecError(
                f"method '{method.label}': step {method.step:g} s does not divide the output "
                f"sample {dt:g} s",
                key="method",
            )
        self.step_s = dt / self.ratio
        self.setup_s = time.perf_counter() - start

    def advance(self, x: np.ndarray, u: np.ndarray, t0: float, n: int) -> np.ndarray:
        from flexctrl.dynamics.fem.newmark_dae import simulate

        self._u[:] = u
        n_q = self.model.n_q
        res = simulate(
            self._problem,
            x[:n_q],
            x[n_q:],
            t0 + n * self.dt,
            self.step_s,
            t0=t0,
            max_violation=np.inf,
            newton_tol=1e-10,
            max_iterations=30,
        )
        rows = slice(self.ratio, None, self.ratio)
        X = np.hstack([res.q[rows], res.qd[rows]])
        if X.shape[0] != n or not np.all(np.isfinite(X)) or np.max(np.abs(X)) > DIVERGED:
            raise SimulationError(
                f"{self.method.label} produced non-finite states between t = {t0:.4g} s and "
                f"{t0 + n * self.dt:.4g} s"
            )
        self.counters["newton_iterations"] = self.counters.get("newton_iterations", 0) + int(
            res.newton_iterations.sum()
        )
        return X


def make_stepper(
    model, method: Method, dt: float = OUTPUT_DT, *, compile: bool | None = None
) -> Stepper:
    """The :class:`Stepper` for ``method`` on ``model``."""
    if method.integrator == "rk4":
        return RK4Stepper(model, method, dt, compile=compile)
    if method.integrator == "newmark":
        return NewmarkStepper(model, method, dt)
    return SundialsStepper(model, method, dt)


# -- drivers -------------------------------------------------------------------------------


@dataclass
class MethodRun:
    """One simulation by a method: states on the output grid and the integration wall time.

    Attributes
    ----------
    time : ndarray
        Output sample times (s), shape (T,).
    states : ndarray
        Shape (T, n_x).
    tip : ndarray
        Tip positions (m), shape (T, 2).
    wall_s : float
        Sum of the ``advance`` calls (s): integration only.
    """

    time: np.ndarray
    states: np.ndarray
    tip: np.ndarray
    wall_s: float
    counters: dict[str, float] = field(default_factory=dict)


def tip_path(model, states: np.ndarray) -> np.ndarray:
    """Tip positions (m), shape (T, 2), of ``states`` (T, n_x)."""
    n = states.shape[0]
    q, qd = states[:, : model.n_q].T, states[:, model.n_q :].T
    return np.asarray(model.functions["tip"].map(n)(q, qd)[0], dtype=float).T[:, :2]


def run_open_loop(stepper: Stepper, x0: np.ndarray, torque: np.ndarray) -> MethodRun:
    """Drive ``stepper`` with held torques ``torque`` (one row per output sample), one call per
    constant piece."""
    stepper.reset()
    n = torque.shape[0]
    X = np.empty((n + 1, x0.size))
    X[0] = x0
    changes = np.flatnonzero(np.any(np.diff(torque, axis=0) != 0.0, axis=1)) + 1
    bounds = [0, *changes.tolist(), n]
    wall = 0.0
    x = np.asarray(x0, dtype=float)
    for a, b in zip(bounds[:-1], bounds[1:]):
        start = time.perf_counter()
        block = stepper.advance(x, torque[a], a * stepper.dt, b - a)
        wall += time.perf_counter() - start
        X[a + 1 : b + 1] = block
        x = block[-1]
    t = np.arange(n + 1) * stepper.dt
    return MethodRun(t, X, tip_path(stepper.model, X), wall, dict(stepper.counters))


def run_closed_loop(
    stepper: Stepper, x0: np.ndarray, controller, sensors, duration: float
) -> MethodRun:
    """Sampled-data loop: ``u = controller.step(t, sensors(x))``, then the stepper holds ``u`` for
    one controller sample.

    The controller is reset first; measurement noise is off (deterministic runs).
    """
    stepper.reset()
    controller.reset()
    Ts = float(controller.sample_time)
    per = int(round(Ts / stepper.dt))
    if per < 1 or abs(per * stepper.dt - Ts) > 1e-9 * Ts:
        raise SpecError(
            f"controller sample time {Ts:g} s is not a whole number of output samples of "
            f"{stepper.dt:g} s",
            key="sample_time",
        )
    n_samples = int(math.ceil(duration / Ts - 1e-9))
    X = np.empty((n_samples * per + 1, x0.size))
    X[0] = x = np.asarray(x0, dtype=float)
    u = np.array(controller.u_previous, dtype=float)
    wall = 0.0
    for k in range(n_samples):
        t = k * Ts
        u = controller.step(t, sensors.measure(x, u, None))
        start = time.perf_counter()
        block = stepper.advance(x, u, t, per)
        wall += time.perf_counter() - start
        X[k * per + 1 : (k + 1) * per + 1] = block
        x = block[-1]
    times = np.arange(X.shape[0]) * stepper.dt
    return MethodRun(times, X, tip_path(stepper.model, X), wall, dict(stepper.counters))


__all__ = [
    "MethodRun",
    "NewmarkStepper",
    "RK4Stepper",
    "Stepper",
    "SundialsStepper",
    "make_stepper",
    "run_closed_loop",
    "run_open_loop",
    "stable_substeps",
    "tip_path",
]
