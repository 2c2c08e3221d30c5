"""Speed against accuracy: simulation methods, a converged reference, tip errors and the Pareto
front.

A *method* is one way of simulating a scene: a model (fidelity and, for assumed
modes, frozen or configuration-scheduled mode shapes) and an integrator with its
step or tolerance.  Methods are spelt as one string (a grid value of the
``speed_vs_accuracy`` study)::

    FIDELITY[+sched]/INTEGRATOR[:VARIANT][@VALUE]

    rigid/rk4@1ms            RK4, step 1 ms
    amm:2/rk4@0.25ms         RK4, 4 steps per 1 ms output sample
    amm:2+sched/rk4@1ms      configuration-scheduled assumed modes
    fem:4/rk4@stable         RK4 at the largest safe step: omega h <= 2.4 for the larger
                             of omega_max and the free-joint spectral radius
    fem:4/newmark@1ms        trapezoidal Newmark, Hessian-of-potential Newton tangents
    amm:2/cvodes@1e-6        CVODES (BDF), rtol 1e-6, atol 1e-2 rtol
    fem:2/idas@1e-5          IDAS (BDF), rtol 1e-5
    amm:2/scipy:DOP853@1e-6  scipy.integrate.solve_ivp, method DOP853, rtol 1e-6

Steps are written ``1ms``, ``250us`` or in seconds (``1e-3``).  Every method
reports its state on the same output grid (``output_dt``, 1 ms); fixed-step
methods take a whole number of steps per output sample.

All methods advance through :class:`Stepper` objects: ``advance(x, u, t0, n)``
holds the torque ``u`` for ``n`` output samples and returns the ``n`` states.  An
open-loop scene is a few such calls (one per constant piece of the torque); a
closed-loop scene one per controller sample.  The wall time of a run is the sum of
the ``advance`` calls only: model building, compilation (cached on disk) and
controller computations are excluded, so ``wall_per_sim_s`` is the integration cost
a user pays per simulated second once the model is built.

Why not the :class:`~flexctrl.sim.integrator.Integrator` classes directly?  Their output
grid is their step, so RK4 on a stiff finite-element model (steps of a few
microseconds) would keep hundreds of thousands of states; here RK4 substeps inside
one compiled call per output sample (as ``rk4_sampler`` of ``tools/fem_report.py``).
CVODES, IDAS and scipy are the package's own integrators (their ``_advance`` hook,
which already integrates a block of held torques); Newmark is
:func:`flexctrl.dynamics.fem.newmark_dae.simulate` on
:func:`flexctrl.dynamics.fem.newmark.model_dae_problem`.

The reference
-------------
A converged tip path per (scene, payload, configuration): the finest affordable
finite-element model with RK4 at its stability-limited step (see
``docs/speed_accuracy.md`` for why not a tight implicit integrator: IDAS at rtol 1e-8
took 70 s per 0.1 s on ``fem:4``).  Its convergence is shown, not assumed:
:func:`compute_reference` also runs the same model with half the step (time
discretisation) and coarser meshes (spatial discretisation) and records their tip
distances from the reference.  References are cached on disk as ``.npz``, keyed by a
hash of everything that determines them (:func:`reference_key`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.errors import SimulationError, SpecError

#: Integrators a method may name.
INTEGRATORS = ("rk4", "newmark", "cvodes", "idas", "scipy")
#: solve_ivp methods for ``scipy:VARIANT``.
SCIPY_METHODS = ("RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA")
#: RK4's safe ``omega h`` for ``@stable`` (the imaginary-axis limit is 2.83).
RK4_SAFETY = 2.4
#: Output sample interval (s) shared by every method and the reference.
OUTPUT_DT = 1e-3
#: A state component beyond this (m, rad, m/s, rad/s) counts as diverged.
DIVERGED = 1e6
#: Bumped when the numerics of a reference change (part of the cache key).
REFERENCE_VERSION = 1

_METHOD = re.compile(
    r"^(?P<fid>[a-z]+(?::\d+)?)(?P<sched>\+sched)?/(?P<integ>[a-z0-9]+)(?::(?P<variant>[A-Za-z0-9]+))?(?:@(?P<value>[^@]+))?$"
)
_STEP = re.compile(r"^(?P<num>[0-9.]+(?:e-?\d+)?)(?P<unit>s|ms|us)?$")


@dataclass(frozen=True)
class Method:
    """One simulation method: model and integrator (see the module docstring for the spelling).

    Attributes
    ----------
    fidelity : str
        ``"rigid"``, ``"amm:N"`` or ``"fem:N"``.
    modes : str
        ``"frozen"`` or ``"scheduled"`` (assumed modes only).
    integrator : str
        One of :data:`INTEGRATORS`.
    step : float or None
        Step (s) of ``rk4`` and ``newmark``; None with ``rk4`` means the stable step.
    rtol : float or None
        Relative tolerance of ``cvodes``, ``idas`` and ``scipy`` (``atol = 1e-2 rtol``).
    variant : str or None
        The solve_ivp method of ``scipy``.
    divide : int
        With ``rk4@stable``: the stable step divided by this (``rk4@stable/2``).
    """

    fidelity: str
    modes: str = "frozen"
    integrator: str = "rk4"
    step: float | None = None
    rtol: float | None = None
    variant: str | None = None
    divide: int = 1

    @property
    def label(self) -> str:
        """The method's spelling (parses back to an equal Method)."""
        head = self.fidelity + ("+sched" if self.modes == "scheduled" else "")
        integ = self.integrator + (f":{self.variant}" if self.variant else "")
        if self.integrator in ("rk4", "newmark"):
            value = (
                ("stable" + (f"/{self.divide}" if self.divide > 1 else ""))
                if self.step is None
                else _step_text(self.step)
            )
        else:
            value = f"{self.rtol:g}"
        return f"{head}/{integ}@{value}"

    @property
    def model_label(self) -> str:
        """The model part: fidelity and, for scheduled modes, ``+sched``."""
        return self.fidelity + ("+sched" if self.modes == "scheduled" else "")

    @property
    def integrator_label(self) -> str:
        """The integrator part (after the slash)."""
        return self.label.split("/", 1)[1]

    @property
    def atol(self) -> float | None:
        """Absolute tolerance (m, rad, m/s, rad/s): ``1e-2 rtol``."""
        return None if self.rtol is None else 1e-2 * self.rtol

    def refined(self) -> Method:
        """The same model with a finer time discretisation: half the step, or rtol / 10."""
        if self.step is not None:
            return dataclasses.replace(self, step=self.step / 2)
        if self.integrator == "rk4":
            return dataclasses.replace(self, divide=2 * self.divide)
        return dataclasses.replace(self, rtol=self.rtol / 10)


def _step_text(step: float) -> str:
    if step >= 1e-3 and abs(step * 1e3 - round(step * 1e3, 3)) < 1e-12:
        return f"{step * 1e3:g}ms"
    return f"{step * 1e6:g}us"


def parse_step(text: str, *, source: str | None = None, key: str | None = None) -> float:
    """A step written ``1ms``, ``250us``, ``0.001s`` or ``1e-3`` (s)."""
    match = _STEP.match(text.strip())
    if not match:
        raise SpecError(
            f"step {text!r} is not allowed; allowed: a positive number with unit s, ms or us "
            "(e.g. 1ms, 250us, 1e-3)",
            source=source,
            key=key,
        )
    value = float(match["num"]) * {"s": 1.0, None: 1.0, "ms": 1e-3, "us": 1e-6}[match["unit"]]
    if not (0 < value <= 0.1):
        raise SpecError(
            f"step {text!r} = {value:g} s is not allowed; allowed: 0 < step <= 0.1 s",
            source=source,
            key=key,
        )
    return value


def parse_method(text: Any, *, source: str | None = None, key: str | None = None) -> Method:
    """Parse a method spelling (see the module docstring).

    Raises
    ------
    SpecError
        Naming the value and what is allowed.
    """
    from flexctrl.spec.fidelity import parse_fidelity

    allowed = (
        "allowed: FIDELITY[+sched]/INTEGRATOR[:VARIANT][@VALUE], e.g. 'amm:2/rk4@1ms', "
        "'fem:4/rk4@stable', "
        "'fem:4/newmark@1ms', 'amm:2/cvodes@1e-6', 'amm:2/scipy:DOP853@1e-6'; integrators: "
        + ", ".join(INTEGRATORS)
    )
    if not isinstance(text, str):
        raise SpecError(f"method {text!r} is not a string; {allowed}", source=source, key=key)
    match = _METHOD.match(text.strip())
    if not match:
        raise SpecError(f"method {text!r} is not spelt right; {allowed}", source=source, key=key)
    fid = parse_fidelity(match["fid"], source=source, key=key)
    if fid.kind not in ("rigid", "amm", "fem"):
        raise SpecError(
            f"method {text!r}: fidelity '{fid}' is not allowed; allowed: rigid, amm:N, fem:N",
            source=source,
            key=key,
        )
    modes = "scheduled" if match["sched"] else "frozen"
    if modes == "scheduled" and fid.kind != "amm":
        raise SpecError(
            f"method {text!r}: '+sched' applies to assumed modes only; allowed: amm:N+sched",
            source=source,
            key=key,
        )
    integ, variant, value = match["integ"], match["variant"], match["value"]
    if integ not in INTEGRATORS:
        import difflib

        hint = difflib.get_close_matches(integ, INTEGRATORS, n=1)
        extra = f" (did you mean '{hint[0]}'?)" if hint else ""
        raise SpecError(
            f"method {text!r}: integrator '{integ}' is not known{extra}; allowed: {', '.join(INTEGRATORS)}",
            source=source,
            key=key,
        )
    if variant is not None and integ != "scipy":
        raise SpecError(
            f"method {text!r}: ':{variant}' applies to scipy only", source=source, key=key
        )
    if integ == "scipy":
        variant = variant or "RK45"
        if variant not in SCIPY_METHODS:
            raise SpecError(
                f"method {text!r}: scipy method '{variant}' is not allowed; allowed: {', '.join(SCIPY_METHODS)}",
                source=source,
                key=key,
            )
    if integ in ("rk4", "newmark"):
        stable = re.match(r"^stable(?:/(\d+))?$", value or "stable")
        if stable and integ == "rk4":
            divide = int(stable[1] or 1)
            if not 1 <= divide <= 64:
                raise SpecError(
                    f"method {text!r}: divisor {divide} is not allowed; allowed: 1 to 64",
                    source=source,
                    key=key,
                )
            return Method(str(fid), modes, integ, None, None, None, divide)
        if value is None:
            raise SpecError(
                f"method {text!r}: newmark needs a step, e.g. newmark@1ms", source=source, key=key
            )
        return Method(str(fid), modes, integ, parse_step(value, source=source, key=key), None, None)
    rtol = 1e-6 if value is None else _rtol(value, text, source, key)
    return Method(str(fid), modes, integ, None, rtol, variant)


def _rtol(value: str, text: str, source: str | None, key: str | None) -> float:
    try:
        rtol = float(value)
    except ValueError:
        rtol = math.nan
    if not (1e-12 <= rtol <= 1e-2):
        raise SpecError(
            f"method {text!r}: tolerance {value!r} is not allowed; allowed: a relative tolerance "
            "in [1e-12, 1e-2]",
            source=source,
            key=key,
        )
    return rtol


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
        """States after each of ``n`` output samples from ``x`` at ``t0`` with torque ``u`` held, shape (n, n_x)."""
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
        self.ratio = max(1, int(round(dt / method.step)))
        if abs(self.ratio * method.step - dt) > 1e-9 * dt:
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
    """Drive ``stepper`` with held torques ``torque`` (one row per output sample), one call per constant piece."""
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
    t = np.arange(X.shape[0]) * stepper.dt
    return MethodRun(t, X, tip_path(stepper.model, X), wall, dict(stepper.counters))


# -- the Pareto front ----------------------------------------------------------------------


def pareto_front(cost: Sequence[float], error: Sequence[float]) -> np.ndarray:
    """Which points are Pareto-optimal (no other point is at least as cheap and as accurate, and
    better in one).

    Parameters
    ----------
    cost, error : sequence of float
        One value per point (lower is better in both); non-finite points are never on the front.

    Returns
    -------
    numpy.ndarray of bool

    Examples
    --------
    >>> pareto_front([1, 2, 3, 2], [3, 1, 0.5, 2]).tolist()
    [True, True, True, False]
    """
    c, e = np.asarray(cost, dtype=float), np.asarray(error, dtype=float)
    if c.shape != e.shape or c.ndim != 1:
        raise ValueError(f"cost and error need the same 1-D shape; got {c.shape} and {e.shape}")
    ok = np.isfinite(c) & np.isfinite(e)
    front = np.zeros(c.size, dtype=bool)
    for i in np.flatnonzero(ok):
        others = ok.copy()
        others[i] = False
        dominated = others & (c <= c[i]) & (e <= e[i]) & ((c < c[i]) | (e < e[i]))
        front[i] = not dominated.any()
    return front


# -- the reference -------------------------------------------------------------------------


def cache_root() -> Path:
    """``$FLEXCTRL_CACHE/accuracy`` or ``./.flexctrl-cache/accuracy``."""
    from flexctrl.user_cache import cache_directory

    return Path(cache_directory()) / "accuracy"


def reference_key(description: dict[str, Any]) -> str:
    """24 hex digits of sha256 of the canonical JSON of ``description`` plus :data:`REFERENCE_VERSION`."""
    text = json.dumps(
        {**description, "version": REFERENCE_VERSION},
        sort_keys=True,
        separators=(",", ":"),
        default=str,
    )
    return hashlib.sha256(text.encode()).hexdigest()[:24]


@dataclass(frozen=True)
class Reference:
    """A reference tip path with its convergence evidence.

    Attributes
    ----------
    time, tip : ndarray
        Output times (s) and tip positions (m).
    method : str
        The reference method's spelling.
    checks : dict
        ``name -> {"method", "rms", "max", "wall_s"}``: tip distance (m) of each
        convergence run from the reference (``"step/2"``: same model, half step;
        ``"fem:N"``: another mesh with RK4 at its stable step).
    wall_s : float
        Integration time of the reference run (s).
    """

    time: np.ndarray
    tip: np.ndarray
    method: str
    checks: dict[str, dict[str, Any]]
    wall_s: float

    def save(self, path: Path) -> None:
        """Write an ``.npz`` (atomically: temporary name, then rename)."""
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp.npz")
        meta = json.dumps({"method": self.method, "checks": self.checks, "wall_s": self.wall_s})
        np.savez_compressed(tmp, time=self.time, tip=self.tip, meta=np.array(meta))
        os.replace(tmp, path)

    @classmethod
    def load(cls, path: Path) -> Reference:
        """Read what :meth:`save` wrote."""
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            return cls(
                np.asarray(data["time"]),
                np.asarray(data["tip"]),
                meta["method"],
                meta["checks"],
                float(meta["wall_s"]),
            )


def compute_reference(
    simulate: Callable[[Method], MethodRun], method: Method, meshes: Sequence[str] = ()
) -> Reference:
    """Run the reference ``method`` and its convergence checks through ``simulate(method) ->
    MethodRun``.

    Checks: the same model with the step halved (``"step/2"``), and each fidelity in
    ``meshes`` with the reference's integrator (coarser meshes show the spatial
    convergence; a finer one bounds the reference's own error).
    """
    from flexctrl.sim.tip_error import tip_error

    ref = simulate(method)
    checks: dict[str, dict[str, Any]] = {}
    candidates = [("step/2", method.refined())] + [
        (m, dataclasses.replace(method, fidelity=m)) for m in meshes
    ]
    for name, other in candidates:
        run = simulate(other)
        err = tip_error(ref.time, ref.tip, run.time, run.tip)
        checks[name] = {"method": other.label, "rms": err.rms, "max": err.max, "wall_s": run.wall_s}
    return Reference(ref.time, ref.tip, method.label, checks, ref.wall_s)


def cached_reference(
    key_data: dict[str, Any], build: Callable[[], Reference], directory: Path | None = None
) -> tuple[Reference, Path, bool]:
    """The reference for ``key_data`` from the disk cache, or ``build()`` it and store it.

    Returns
    -------
    reference, path, hit
    """
    directory = cache_root() if directory is None else Path(directory)
    path = directory / f"reference_{reference_key(key_data)}.npz"
    if path.is_file():
        try:
            return Reference.load(path), path, True
        except (OSError, ValueError, KeyError):
            pass  # unreadable (e.g. a half-written file from a killed run): recompute
    ref = build()
    ref.save(path)
    (path.with_suffix(".json")).write_text(
        json.dumps(
            {"key": key_data, "method": ref.method, "checks": ref.checks}, indent=1, default=str
        )
    )
    return ref, path, False
