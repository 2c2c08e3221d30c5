"""The state of one sampled run: the kept states and torques, the samples done, a divergence."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from flexctrl.loop.monitors import MODAL_BOUND, RATE_BOUND
from flexctrl.sim.bound import BoundFunction
from flexctrl.sim.rk4 import RK4_STABILITY_LIMIT


class LoopRun:
    """One sampled run of a controller on a plant, sample by sample or chained in CasADi.

    Parameters
    ----------
    plant : flexctrl.dynamics.model.Model
        The controlled arm.
    controller : flexctrl.control.controller.Controller
        Designed, reset and tracking its reference.
    sensors : Sensors
        The controller's sensor kinds built on the plant.
    advance : casadi.Function
        ``advance(x, u, dt) -> X`` (n_x, substeps): the plant over one held sample.
    x0 : array_like
        Initial plant state.
    dt : float
        Plant step (s).
    substeps : int
        Plant steps per controller sample.
    stride : int
        Every ``stride``-th plant state is kept (a divisor of ``substeps``).
    n_samples : int
        Controller samples of the run.
    rng : numpy.random.Generator, optional
        Measurement noise; None measures exactly.
    monitor : callable, optional
        ``monitor(t, x) -> str | None`` (:func:`flexctrl.loop.monitors.divergence_monitor`).
    changes : sequence of (float, Model, Sensors, casadi.Function), optional
        Plant swaps ``(time s, plant, its sensors, its advance)``, by time: from the first
        sample at or after ``time`` the run continues on the new plant from the same state
        (a payload grasped or released at rest: same coordinates, new masses and modes).
    """

    def __init__(
        self,
        plant,
        controller,
        sensors,
        advance: ca.Function,
        x0,
        *,
        dt: float,
        substeps: int,
        stride: int,
        n_samples: int,
        rng: np.random.Generator | None = None,
        monitor=None,
        changes=(),
    ):
        self.plant, self.controller, self.sensors = plant, controller, sensors
        self.changes = sorted(changes, key=lambda change: change[0])
        self.advance, self.rng, self.monitor = advance, rng, monitor
        self.dt, self.substeps, self.stride, self.n_samples = dt, substeps, stride, n_samples
        self.per = substeps // stride
        self.X = np.empty((n_samples * self.per + 1, plant.n_x))
        self.U = np.empty((n_samples * self.per + 1, plant.n_u))
        self.X[0] = self.x = np.asarray(x0, dtype=float)
        self.u = np.array(controller.u_previous, dtype=float)
        self.done = 0
        self.end = n_samples * self.per + 1
        self.divergence: dict[str, Any] | None = None
        # the per-sample calls, bound to arrays for this run alone (a Dask worker may run two
        # runs in threads)
        self._outputs, self._advance = BoundFunction(sensors.function), BoundFunction(advance)
        self._monitor = monitor.for_run() if hasattr(monitor, "for_run") else monitor

    def python_sample(self, k: int) -> bool:
        """Run sample ``k`` in Python; True when the run diverged in it."""
        Ts, per = self.controller.sample_time, self.per
        t = k * Ts
        while self.changes and t >= self.changes[0][0] - 1e-9 * Ts:
            _, self.plant, self.sensors, advance = self.changes.pop(0)
            self._outputs, self._advance = (
                BoundFunction(self.sensors.function),
                BoundFunction(advance),
            )
        y = self.sensors.with_noise(self._outputs(self.x, self.u)[0].ravel(), self.rng)
        self.u = u = self.controller.step(t, y)
        block = self._advance(self.x, u, self.dt)[0]
        self.X[k * per + 1 : (k + 1) * per + 1] = block[self.stride - 1 :: self.stride]
        self.U[k * per : (k + 1) * per] = u
        self.x = block[-1]
        self.done = k + 1
        return self.check(k, block)

    def check(self, k: int, block: np.ndarray) -> bool:
        """Whether the states ``block`` of sample ``k`` (ending at ``self.x``) diverge.

        A divergence is recorded (:attr:`divergence`) and cuts the run at the last finite state.
        """
        plant, Ts = self.plant, self.controller.sample_time
        t_end = k * Ts + Ts
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
        last = (k + 1) * self.per + 1
        finite = np.all(np.isfinite(self.X[:last]), axis=1)
        self.end = max(int(np.argmin(finite)) if not np.all(finite) else last, 2)
        self.divergence = {
            "time": float(t_end),
            "reason": reason,
            "message": self._divergence_message(t_end, reason),
        }
        return True

    def _divergence_message(self, t_end: float, reason: str) -> str:
        """What diverged, when, and the causes that apply.

        The RK4 step is named only when it is within a factor 2 of RK4's stability bound for
        the locked-joint modes; the design's diagnosis
        (:attr:`~flexctrl.control.controller.Controller.design_diagnosis`) when it flagged
        undamped or near-aliased modes.
        """
        plant, Ts, dt = self.plant, self.controller.sample_time, self.dt
        stable_step = RK4_STABILITY_LIMIT / max(plant.omega_max, 1e-12)
        cause = "the controller does not stabilise this plant"
        diagnosis = getattr(self.controller, "design_diagnosis", None)
        if diagnosis is not None and diagnosis.flagged:
            cause += f", likely because {diagnosis.message()}"
        if dt > 0.5 * stable_step:
            cause += (
                " (or the plant step is too large for RK4: stable below "
                f"~{stable_step:.3g} s for the locked-joint modes)"
            )
        return (
            f"closed loop diverged at t = {t_end:.4g} s ({reason}; plant step {dt:g} s, "
            f"controller sample {Ts:g} s, plant omega_max {plant.omega_max:.4g} rad/s): {cause}"
        )

    def kept(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Times (s), states and held torques (N m) kept so far (the last torque the last held)."""
        X, U = self.X[: self.end], self.U[: self.end]
        U[-1] = self.u
        return np.arange(X.shape[0]) * (self.dt * self.stride), X, U
