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

That is the ``loop = "python"`` path: one Python iteration per sample, for controllers that
optimise or schedule per sample (MPC, NMPC, a gain schedule), and for plants whose fine step
would make one call's states too many to hold.  A controller whose law is a CasADi map
(:meth:`~flexctrl.control.controller.Controller.sampled_law`: LQR, LQG, PD, shaped) runs,
after its first sample, every remaining sample in ONE CasADi call (``loop = "compiled"``,
:mod:`flexctrl.loop.compiled`; ``"auto"``, the default, uses it when the controller offers
it).  Both paths do the same arithmetic in the plant and the controller; the compiled output
map and the controller's matrix products can differ in the last digits (the tests hold them
within 1e-9 relative).

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
from flexctrl.loop.monitors import MODAL_BOUND, RATE_BOUND
from flexctrl.loop.plant_step import advance_function, output_map
from flexctrl.sim.bound import BoundFunction, evaluate
from flexctrl.sim.rk4 import RK4_STABILITY_LIMIT
from flexctrl.sim.trajectory import LazyEnergies, Trajectory

# : How the samples are run: ``"python"`` (one iteration per sample), ``"compiled"`` (one CasADi
# call for all but
# : the first; an error for a controller without a :meth:`sampled_law`), ``"auto"`` (compiled when
# offered).
LOOPS = ("auto", "compiled", "python")


def mapped(model, name: str, count: int, *args):
    return model.functions[name].map(count)(*args)


def tip_positions(model, X: np.ndarray, compile: bool | None = None) -> np.ndarray:
    """The tip positions (m, shape (T, 2)) of the states ``X`` (rows), from the compiled map without
    energies.

    The same values as :attr:`Trajectory.tip` of :func:`trajectory_from_states` (compiled):
    the fidelity chooser compares rungs by them.
    """
    return evaluate(output_map(model, X.shape[0], compile, energies=False), X)[0][:, 0:2]


def trajectory_from_states(
    model,
    t: np.ndarray,
    X: np.ndarray,
    U: np.ndarray,
    meta: dict[str, Any],
    *,
    compiled: bool = False,
    compile: bool | None = None,
) -> Trajectory:
    """A :class:`Trajectory` with energies, tip and deflections of the states ``X`` (rows).

    ``compiled``: from the compiled output maps (:func:`flexctrl.loop.plant_step.output_map`),
    else by mapped calls of the model's Functions in CasADi's virtual machine.  The energies
    are evaluated when first read (:class:`~flexctrl.sim.trajectory.LazyEnergies`): no metric
    of the loop reads them, and on fine models they cost several times the tip and
    deflections.
    """
    count = t.size
    values: Any
    if compiled:
        Y = evaluate(output_map(model, count, compile, energies=False), X)[0]
        tip, deflection = Y[:, 0:2], Y[:, 2:]

        def compute():
            E = evaluate(output_map(model, count, compile), X)[0]
            return E[:, 0], E[:, 1], E[:, 2]

        values = LazyEnergies(compute)
    else:
        q, qd = X[:, : model.n_q].T, X[:, model.n_q :].T
        tip = np.array(mapped(model, "tip", count, q, qd)[0], dtype=float).T
        deflection = np.array(mapped(model, "deflection", count, q)[0], dtype=float).T

        def compute_vm():
            return tuple(
                np.array(v, dtype=float).ravel() for v in mapped(model, "energies", count, q, qd)
            )

        values = LazyEnergies(compute_vm)
    return Trajectory(
        time=t,
        states=X,
        inputs=U,
        coordinate_names=model.coordinate_names,
        energies=values,
        tip=tip,
        deflections=deflection,
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
    loop: str = "auto",
) -> tuple[Trajectory, np.ndarray]:
    """Run ``controller`` on ``plant`` from ``x0`` for ``duration`` s with plant step ``dt`` s.

    Parameters
    ----------
    monitor : callable, optional
        ``monitor(t, x) -> str | None`` called with the plant state at the end of every
        controller sample; a string (why the run is diverging) stops it like a
        non-finite state.  A monitor with a ``flags(X)`` method
        (:class:`~flexctrl.loop.monitors.LoopMonitor`) is asked about all states at once
        on the compiled path.
    stop_on_divergence : bool
        On divergence, return the trajectory up to the last finite state with
        ``meta["divergence"] = {"time": t (s), "reason": str}`` instead of raising.
    loop : {"auto", "compiled", "python"}
        How the samples are run (:data:`LOOPS`, module docstring).  The energies, tip and
        deflections come from the compiled output map except with ``"python"`` (mapped calls
        in CasADi's virtual machine, which compile nothing for the run's length).

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
        loop=loop,
    )
    return trajectory_from_states(
        plant, t, X, U, meta, compiled=loop != "python", compile=compile
    ), samples


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
    loop: str = "auto",
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any], np.ndarray]:
    """The loop of :func:`simulate_closed_loop` without the trajectory's derived signals.

    Parameters
    ----------
    stride : int
        Keep every ``stride``-th plant sample (a whole divisor of ``Ts/dt``), e.g. to
        compare runs at different plant steps on a common grid of ``stride * dt`` s.
    loop : {"auto", "compiled", "python"}
        See :func:`simulate_closed_loop`.

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
    substeps = _checked_substeps(loop, Ts, dt, stride)
    setup = time.perf_counter()
    advance, compiled = advance_function(plant, substeps, compile)
    setup = time.perf_counter() - setup
    run = LoopRun(
        plant,
        controller,
        sensors or controller.sensors,
        rng,
        monitor,
        dt,
        substeps,
        stride,
        int(math.ceil(duration / Ts - 1e-9)),
        advance,
        x0,
    )
    wall = time.perf_counter()
    used = _run_samples(run, controller, loop)
    if run.divergence is not None and not stop_on_divergence:
        raise SimulationError(run.divergence["message"])
    X, U = run.X[: run.end], run.U[: run.end]
    U[-1] = run.u
    t = np.arange(X.shape[0]) * (dt * stride)
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


def _checked_substeps(loop: str, Ts: float, dt: float, stride) -> int:
    """Plant steps per sample, after ``loop``, ``dt`` and ``stride`` are checked."""
    if loop not in LOOPS:
        raise SpecError(
            f"value {loop!r} is not allowed; allowed: {', '.join(map(repr, LOOPS))}", key="loop"
        )
    substeps = int(round(Ts / dt))
    if substeps < 1 or abs(substeps * dt - Ts) > 1e-9 * Ts:
        raise SpecError(
            f"plant step {dt:g} s does not divide the controller sample time {Ts:g} s; allowed: "
            "Ts/dt a whole number",
            key="dt",
        )
    if isinstance(stride, bool) or not isinstance(stride, int) or stride < 1 or substeps % stride:
        raise SpecError(
            f"value {stride!r} is not allowed; allowed: a whole divisor of Ts/dt = {substeps}",
            key="stride",
        )
    return substeps


def _run_samples(run: LoopRun, controller, loop: str) -> str:
    """Run the samples: the first in Python, the rest in one CasADi call when the controller's
    law allows it; returns which loop ran the samples after the first."""
    python_until = run.n_samples if loop == "python" else min(1, run.n_samples)
    for k in range(python_until):
        if run.python_sample(k):
            return "python"
    if run.divergence is not None or run.done >= run.n_samples:
        return "python"
    law = controller.sampled_law()
    if law is None and loop == "compiled":
        raise SpecError(
            f"the {type(controller).__name__} has no sampled law (it optimises or schedules per "
            "sample); allowed: loop = 'python' or 'auto'",
            key="loop",
        )
    if law is None:
        for k in range(run.done, run.n_samples):
            if run.python_sample(k):
                break
        return "python"
    run_compiled(run, law)
    return "compiled"


class LoopRun:
    """The state of one sampled run: the kept states and torques, the samples done, a divergence."""

    def __init__(
        self,
        plant,
        controller,
        sensors,
        rng,
        monitor,
        dt: float,
        substeps: int,
        stride: int,
        n_samples: int,
        advance,
        x0,
    ):
        self.plant, self.controller, self.sensors, self.rng, self.monitor = (
            plant,
            controller,
            sensors,
            rng,
            monitor,
        )
        self.dt, self.substeps, self.stride, self.n_samples, self.advance = (
            dt,
            substeps,
            stride,
            n_samples,
            advance,
        )
        self.per = substeps // stride
        self.X = np.empty((n_samples * self.per + 1, plant.n_x))
        self.U = np.empty((n_samples * self.per + 1, plant.n_u))
        self.X[0] = self.x = np.asarray(x0, dtype=float)
        self.u = np.array(controller.u_previous, dtype=float)
        self.done = 0
        self.end = n_samples * self.per + 1
        self.divergence = None
        # the Python loop's per-sample calls, bound to arrays for this run alone (a Dask worker may
        # run two in threads)
        self._outputs, self._advance = BoundFunction(sensors.function), BoundFunction(advance)
        self._monitor = monitor.for_run() if hasattr(monitor, "for_run") else monitor

    def python_sample(self, k: int) -> bool:
        """Run sample ``k`` in Python; True when the run diverged in it."""
        Ts, per = self.controller.sample_time, self.per
        t = k * Ts
        y = self.sensors.with_noise(self._outputs(self.x, self.u)[0].ravel(), self.rng)
        self.u = u = self.controller.step(t, y)
        block = self._advance(self.x, u, self.dt)[0]
        self.X[k * per + 1 : (k + 1) * per + 1] = block[self.stride - 1 :: self.stride]
        self.U[k * per : (k + 1) * per] = u
        self.x = block[-1]
        self.done = k + 1
        return self.check(k, block)

    def check(self, k: int, block: np.ndarray) -> bool:
        """Whether the states ``block`` of sample ``k`` (ending at ``self.x``) diverge; records it and cuts the run."""
        plant, t_end = self.plant, k * self.controller.sample_time + self.controller.sample_time
        reason = None
        if not np.all(np.isfinite(block)):
            reason = "non-finite plant state"
        elif np.max(np.abs(block[:, plant.n_u : plant.n_q]), initial=0.0) > MODAL_BOUND:
            reason = f"a modal coordinate beyond {MODAL_BOUND:g} m"
        elif np.max(np.abs(block[:, plant.n_q :])) > RATE_BOUND:
            reason = f"a rate beyond {RATE_BOUND:g}"
        elif self._monitor is not None:
            reason = self._monitor(t_end, self.x)
        if reason is None:
            return False
        Ts, dt = self.controller.sample_time, self.dt
        message = (
            f"closed loop diverged at t = {t_end:.4g} s ({reason}; plant step {dt:g} s, "
            "controller sample "
            f"{Ts:g} s, plant omega_max {plant.omega_max:.4g} rad/s): the controller does not "
            "stabilise "
            f"this plant (or the plant step is too large for RK4: stable below "
            f"~{RK4_STABILITY_LIMIT / max(plant.omega_max, 1e-12):.3g} s for the locked-joint modes)"
        )
        last = (k + 1) * self.per + 1
        finite = np.all(np.isfinite(self.X[:last]), axis=1)
        self.end = max(int(np.argmin(finite)) if not np.all(finite) else last, 2)
        self.divergence = {"time": float(t_end), "reason": reason, "message": message}
        return True
