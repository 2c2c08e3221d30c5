"""The sampled-data loop: the controller at its own rate, the plant advanced between samples.

Per controller sample (period ``Ts = controller.sample_time``):

1. the *plant's* sensors measure the plant state (noise from the controller's
   sensor settings when enabled; a real strain gauge reads the true curvature, so
   the measurement model is built on the plant, not on the design model,
   :mod:`flexctrl.loop.mismatch`);
2. ``u = controller.step(t, y)`` (clipped to the torque limits by the controller);
3. the plant advances ``Ts`` with ``u`` held (zero-order hold) by ``Ts/dt`` RK4 steps
   inside one compiled CasADi call that also returns the intermediate states
   (:mod:`flexctrl.loop.plant_step`), so the tip vibration is recorded at the plant rate.

The first sample runs in Python (estimators start from the first measurement, the shaped
step from the first joint angles).  After it, a controller whose law is a CasADi map
(:meth:`~flexctrl.control.controller.Controller.sampled_law`: LQR, LQG, PD, shaped) runs
the remaining samples chained in CasADi (:mod:`flexctrl.loop.compiled`); a controller
that optimises or schedules per sample (MPC, NMPC, gain schedule) is called once per
sample from Python.  Both do the same arithmetic in the plant and the controller; the
controller's matrix products in CasADi and in NumPy can differ in the last digits.

The energies, tip and deflections come from the plant's compiled output map; the
energies are evaluated when first read (:class:`~flexctrl.sim.trajectory.LazyEnergies`):
no metric reads them, and the kinetic energy costs most of the outputs.

Instability is detected, never a silent NaN: after every sample the state must be
finite, its modal coordinates and rates within :data:`~flexctrl.loop.monitors.MODAL_BOUND`
and :data:`~flexctrl.loop.monitors.RATE_BOUND`, and the optional ``monitor`` must not
object (:func:`flexctrl.loop.monitors.divergence_monitor`).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from flexctrl.errors import SimulationError, SpecError
from flexctrl.loop.compiled import run_compiled
from flexctrl.loop.plant_step import advance_function, output_map
from flexctrl.loop.run_state import LoopRun
from flexctrl.sim.bound import evaluate
from flexctrl.sim.trajectory import LazyEnergies, Trajectory


def tip_positions(model, X: np.ndarray, compile: bool | None = None) -> np.ndarray:
    """The tip positions (m, shape (T, 2)) of the states ``X`` (rows).

    From the compiled output map without the energies: the same values as the
    :attr:`Trajectory.tip` of :func:`trajectory_from_states`.  The fidelity chooser compares
    rungs by them.
    """
    return evaluate(output_map(model, X.shape[0], compile, energies=False), X)[0][:, 0:2]


def trajectory_from_states(
    model,
    t: np.ndarray,
    X: np.ndarray,
    U: np.ndarray,
    meta: dict[str, Any],
    *,
    compile: bool | None = None,
) -> Trajectory:
    """A :class:`Trajectory` with the energies, tip and deflections of the states ``X`` (rows).

    The tip and deflections come from the compiled output map without the energies
    (:func:`flexctrl.loop.plant_step.output_map`); the energies from the full map when
    first read (:class:`~flexctrl.sim.trajectory.LazyEnergies`).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The plant.
    t : numpy.ndarray
        Times (s), shape (T,).
    X, U : numpy.ndarray
        States and held torques (N m), shapes (T, n_x) and (T, n_u).
    meta : dict
        The run's facts (:func:`integrate_closed_loop`).
    compile : bool, optional
        Compile the output maps to C (default: when a compiler is present).
    """
    count = t.size
    Y = evaluate(output_map(model, count, compile, energies=False), X)[0]

    def energies():
        E = evaluate(output_map(model, count, compile), X)[0]
        return E[:, 0], E[:, 1], E[:, 2]

    return Trajectory(
        time=t,
        states=X,
        inputs=U,
        coordinate_names=model.coordinate_names,
        energies=LazyEnergies(energies),
        tip=Y[:, 0:2],
        deflections=Y[:, 2:],
        meta=meta,
    )


def simulate_closed_loop(
    plant,
    controller,
    x0: np.ndarray,
    duration: float,
    dt: float,
    *,
    sensors=None,
    rng: np.random.Generator | None = None,
    compile: bool | None = None,
    monitor=None,
    stop_on_divergence: bool = False,
    plant_changes=(),
) -> tuple[Trajectory, np.ndarray]:
    """Run ``controller`` on ``plant`` from ``x0`` for ``duration`` s with plant step ``dt`` s.

    Parameters
    ----------
    plant : flexctrl.dynamics.model.Model
        The controlled arm.
    controller : flexctrl.control.controller.Controller
        Designed, reset and tracking its reference.
    x0 : numpy.ndarray
        Initial plant state ``(q, qd)``.
    duration : float
        Simulated time (s).
    dt : float
        Plant RK4 step (s), a whole fraction of the controller's sample time.
    sensors : Sensors, optional
        The controller's sensor kinds built on the plant (default the controller's own).
    rng : numpy.random.Generator, optional
        Measurement noise at the sensors' levels; None measures exactly.
    compile : bool, optional
        Compile the plant step and output maps to C (default: when a compiler is present).
    monitor : callable, optional
        ``monitor(t, x) -> str | None`` called with the plant state at the end of every
        controller sample; a string (why the run is diverging) stops it like a
        non-finite state.  A monitor with a ``flags(X)`` method
        (:class:`~flexctrl.loop.monitors.LoopMonitor`) is asked about all states at once
        when the samples are chained in CasADi.
    stop_on_divergence : bool
        On divergence, return the trajectory up to the last finite state with
        ``meta["divergence"] = {"time": t (s), "reason": str}`` instead of raising.
    plant_changes : sequence of (float, Model, Sensors)
        ``(time s, plant, its sensors)``: the plant the run continues on from the first sample
        at or after ``time`` (same coordinates; a payload grasped or released at rest).  The
        samples then run in Python, and the tip and deflections after a change are the new
        plant's.

    Returns
    -------
    trajectory : Trajectory
        At the plant rate; ``inputs`` are the held torques.
    sample_times : ndarray
        Times (s) at which the controller was called.

    Raises
    ------
    SimulationError
        The plant diverged (unless ``stop_on_divergence``).
    """
    t, X, U, meta, samples = integrate_closed_loop(
        plant,
        controller,
        x0,
        duration,
        dt,
        sensors=sensors,
        rng=rng,
        compile=compile,
        monitor=monitor,
        stop_on_divergence=stop_on_divergence,
        plant_changes=plant_changes,
    )
    trajectory = trajectory_from_states(plant, t, X, U, meta, compile=compile)
    for time_s, new_plant, _sensors in plant_changes:
        after = t >= time_s - 1e-9 * controller.sample_time
        if np.any(after):
            Y = evaluate(output_map(new_plant, int(after.sum()), compile, energies=False), X[after])
            trajectory.tip[after] = Y[0][:, 0:2]
            trajectory.deflections[after] = Y[0][:, 2:]
    return trajectory, samples


def integrate_closed_loop(
    plant,
    controller,
    x0: np.ndarray,
    duration: float,
    dt: float,
    *,
    sensors=None,
    rng: np.random.Generator | None = None,
    compile: bool | None = None,
    monitor=None,
    stop_on_divergence: bool = False,
    stride: int = 1,
    plant_changes=(),
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any], np.ndarray]:
    """The loop of :func:`simulate_closed_loop` without the trajectory's derived signals.

    Parameters
    ----------
    plant, controller, x0, duration, dt, sensors, rng, compile, monitor, stop_on_divergence
        As in :func:`simulate_closed_loop`.
    stride : int
        Keep every ``stride``-th plant sample (a whole divisor of ``Ts/dt``), e.g. to
        compare runs at different plant steps on a common grid of ``stride * dt`` s.
    plant_changes : sequence of (float, Model, Sensors)
        As in :func:`simulate_closed_loop`.

    Returns
    -------
    t : ndarray
        Kept sample times (s), shape (T,).
    X, U : ndarray
        States and held torques (N m) at those times, shapes (T, n_x) and (T, n_u).
    meta : dict
        ``integrator``, ``dt`` (s), ``sample_time`` (s), ``wall_time_s`` (s, the loop),
        ``compiled``, ``divergence``, ``stride``, ``setup_time_s`` (s, building and
        compiling or loading the plant's step function), ``loop`` (``"python"`` or
        ``"compiled"``: how the samples after the first ran).
    sample_times : ndarray
        Times (s) at which the controller was called.
    """
    Ts = controller.sample_time
    substeps = _substeps(Ts, dt)
    _check_stride(stride, substeps)
    setup = time.perf_counter()
    advance, compiled = advance_function(plant, substeps, compile)
    changes = [
        (float(when), new, sensors, advance_function(new, substeps, compile)[0])
        for when, new, sensors in plant_changes
    ]
    setup = time.perf_counter() - setup
    run = LoopRun(
        plant,
        controller,
        sensors or controller.sensors,
        advance,
        x0,
        dt=dt,
        substeps=substeps,
        stride=stride,
        n_samples=int(math.ceil(duration / Ts - 1e-9)),
        rng=rng,
        monitor=monitor,
        changes=changes,
    )
    wall = time.perf_counter()
    used = run_samples(run)
    if run.divergence is not None and not stop_on_divergence:
        raise SimulationError(run.divergence["message"])
    t, X, U = run.kept()
    meta = {
        "integrator": "rk4",
        "dt": dt,
        "sample_time": Ts,
        "wall_time_s": time.perf_counter() - wall,
        "compiled": compiled,
        "divergence": run.divergence,
        "stride": stride,
        "setup_time_s": setup,
        "loop": used,
    }
    return t, X, U, meta, np.arange(run.done) * Ts


def run_samples(run: LoopRun) -> str:
    """Run every sample of ``run``: the first in Python, the rest chained in CasADi if possible.

    Returns how the samples after the first ran: ``"compiled"`` (the controller's
    :meth:`sampled_law`, :func:`flexctrl.loop.compiled.run_compiled`) or ``"python"``
    (one ``controller.step`` per sample: a controller that optimises or schedules).
    """
    if run.n_samples and run.python_sample(0):
        return "python"
    if run.done >= run.n_samples:
        return "python"
    law = None if run.changes else run.controller.sampled_law()
    if law is None:
        for k in range(run.done, run.n_samples):
            if run.python_sample(k):
                break
        return "python"
    run_compiled(run, law)
    return "compiled"


def _substeps(Ts: float, dt: float) -> int:
    """Plant steps per controller sample; :class:`SpecError` unless ``dt`` divides ``Ts``."""
    substeps = int(round(Ts / dt))
    if substeps < 1 or abs(substeps * dt - Ts) > 1e-9 * Ts:
        raise SpecError(
            f"plant step {dt:g} s does not divide the controller sample time {Ts:g} s; "
            "allowed: Ts/dt a whole number",
            key="dt",
        )
    return substeps


def _check_stride(stride: Any, substeps: int) -> None:
    if isinstance(stride, bool) or not isinstance(stride, int) or stride < 1 or substeps % stride:
        raise SpecError(
            f"value {stride!r} is not allowed; allowed: a whole divisor of Ts/dt = {substeps}",
            key="stride",
        )
