"""The sampled-data loop: the controller at its own rate, the plant advanced between samples.

Per controller sample (period ``Ts = controller.sample_time``):

1. the *plant's* sensors measure the plant state (noise from the controller's
   sensor settings when enabled; a real strain gauge reads the true curvature, so
   the measurement model is built on the plant, not on the design model,
   :mod:`flexctrl.loop.mismatch`);
2. ``u = controller.step(t, y)`` (clipped to the torque limits by the controller);
3. the plant advances ``Ts`` with ``u`` held (zero-order hold) by ``Ts/dt`` RK4 steps
   inside ONE compiled CasADi call that also returns the intermediate states
   (:mod:`flexctrl.loop.plant_step`), so the tip vibration is recorded at the plant rate.

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
from flexctrl.loop.monitors import MODAL_BOUND, RATE_BOUND
from flexctrl.loop.plant_step import advance_function
from flexctrl.sim.rk4 import RK4_STABILITY_LIMIT
from flexctrl.sim.trajectory import Trajectory


def mapped(model, name: str, count: int, *args):
    return model.functions[name].map(count)(*args)


def trajectory_from_states(model, t: np.ndarray, X: np.ndarray, U: np.ndarray, meta: dict[str, Any]) -> Trajectory:
    """A :class:`Trajectory` with energies, tip and deflections evaluated by mapped CasADi calls."""
    count = t.size
    q, qd = X[:, : model.n_q].T, X[:, model.n_q :].T
    kin, el, grav = (np.array(v, dtype=float).ravel() for v in mapped(model, "energies", count, q, qd))
    tip = np.array(mapped(model, "tip", count, q, qd)[0], dtype=float).T
    deflection = np.array(mapped(model, "deflection", count, q)[0], dtype=float).T
    energies = {"E_kin": kin, "E_el": el, "E_grav": grav, "E_total": kin + el + grav}
    return Trajectory(time=t, states=X, inputs=U, coordinate_names=model.coordinate_names, energies=energies,
                      tip=tip, deflections=deflection, meta=meta)


def simulate_closed_loop(plant, controller, x0: np.ndarray, duration: float, dt: float, *,
                         sensors=None, rng: np.random.Generator | None = None, compile: bool | None = None,
                         monitor=None, stop_on_divergence: bool = False) -> tuple[Trajectory, np.ndarray]:
    """Run ``controller`` on ``plant`` from ``x0`` for ``duration`` s with plant step ``dt`` s.

    Parameters
    ----------
    monitor : callable, optional
        ``monitor(t, x) -> str | None`` called with the plant state at the end of every
        controller sample; a string (why the run is diverging) stops it like a
        non-finite state.
    stop_on_divergence : bool
        On divergence, return the trajectory up to the last finite state with
        ``meta["divergence"] = {"time": t (s), "reason": str}`` instead of raising.

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
    t, X, U, meta, samples = integrate_closed_loop(plant, controller, x0, duration, dt, sensors=sensors, rng=rng,
                                                   compile=compile, monitor=monitor,
                                                   stop_on_divergence=stop_on_divergence)
    return trajectory_from_states(plant, t, X, U, meta), samples


def integrate_closed_loop(plant, controller, x0: np.ndarray, duration: float, dt: float, *,
                          sensors=None, rng: np.random.Generator | None = None, compile: bool | None = None,
                          monitor=None, stop_on_divergence: bool = False, stride: int = 1
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any], np.ndarray]:
    """The loop of :func:`simulate_closed_loop` without the trajectory's derived signals.

    Parameters
    ----------
    stride : int
        Keep every ``stride``-th plant sample (a whole divisor of ``Ts/dt``), e.g. to
        compare runs at different plant steps on a common grid of ``stride * dt`` s.

    Returns
    -------
    t : ndarray
        Kept sample times (s), shape (T,).
    X, U : ndarray
        States and held torques (N m) at those times, shapes (T, n_x) and (T, n_u).
    meta : dict
        ``integrator``, ``dt`` (s), ``sample_time`` (s), ``wall_time_s`` (s, the loop),
        ``compiled``, ``divergence``, ``stride``, ``setup_time_s`` (s, building and
        compiling or loading the plant's step function).
    sample_times : ndarray
        Times (s) at which the controller was called.
    """
    Ts = controller.sample_time
    substeps = int(round(Ts / dt))
    if substeps < 1 or abs(substeps * dt - Ts) > 1e-9 * Ts:
        raise SpecError(f"plant step {dt:g} s does not divide the controller sample time {Ts:g} s; allowed: Ts/dt a whole number", key="dt")
    if isinstance(stride, bool) or not isinstance(stride, int) or stride < 1 or substeps % stride:
        raise SpecError(f"value {stride!r} is not allowed; allowed: a whole divisor of Ts/dt = {substeps}", key="stride")
    sensors = sensors or controller.sensors
    setup = time.perf_counter()
    advance, compiled = advance_function(plant, substeps, compile)
    setup = time.perf_counter() - setup
    per = substeps // stride
    n_samples = int(math.ceil(duration / Ts - 1e-9))
    X = np.empty((n_samples * per + 1, plant.n_x))
    U = np.empty((n_samples * per + 1, plant.n_u))
    X[0] = x = np.asarray(x0, dtype=float)
    u = np.array(controller.u_previous, dtype=float)
    n_joints = plant.n_u
    wall = time.perf_counter()
    divergence = None
    end = n_samples * per + 1
    samples_done = n_samples
    for k in range(n_samples):
        t = k * Ts
        u = controller.step(t, sensors.measure(x, u, rng))
        block = np.asarray(advance(x, u, dt), dtype=float).T
        rows = slice(k * per + 1, (k + 1) * per + 1)
        X[rows] = block[stride - 1 :: stride]
        U[k * per : (k + 1) * per] = u
        x = block[-1]
        reason = None
        if not np.all(np.isfinite(block)):
            reason = "non-finite plant state"
        elif np.max(np.abs(block[:, n_joints : plant.n_q]), initial=0.0) > MODAL_BOUND:
            reason = f"a modal coordinate beyond {MODAL_BOUND:g} m"
        elif np.max(np.abs(block[:, plant.n_q :])) > RATE_BOUND:
            reason = f"a rate beyond {RATE_BOUND:g}"
        elif monitor is not None:
            reason = monitor(t + Ts, x)
        if reason is not None:
            message = (f"closed loop diverged at t = {t + Ts:.4g} s ({reason}; plant step {dt:g} s, controller sample "
                       f"{Ts:g} s, plant omega_max {plant.omega_max:.4g} rad/s): the controller does not stabilise "
                       f"this plant (or the plant step is too large for RK4: stable below "
                       f"~{RK4_STABILITY_LIMIT / max(plant.omega_max, 1e-12):.3g} s for the locked-joint modes)")
            if not stop_on_divergence:
                raise SimulationError(message)
            finite = np.all(np.isfinite(X[: (k + 1) * per + 1]), axis=1)
            end = int(np.argmin(finite)) if not np.all(finite) else (k + 1) * per + 1
            end = max(end, 2)
            divergence = {"time": float(t + Ts), "reason": reason, "message": message}
            samples_done = k + 1
            break
    X, U = X[:end], U[:end]
    U[-1] = u
    t = np.arange(X.shape[0]) * (dt * stride)
    meta = {"integrator": "rk4", "dt": dt, "sample_time": Ts, "wall_time_s": time.perf_counter() - wall,
            "compiled": compiled, "divergence": divergence, "stride": stride, "setup_time_s": setup}
    return t, X, U, meta, np.arange(samples_done) * Ts

