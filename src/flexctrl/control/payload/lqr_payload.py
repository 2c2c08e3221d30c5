"""The payload-aware LQR (LQG): identify the payload on line, run the design at its light side.

Built by :func:`design_lqr_payload` from an LQR file with a ``[payload]`` table
(:class:`~flexctrl.spec.payload_settings.PayloadSettings`).  Every sample:

1. the bank (:class:`~flexctrl.control.payload.bank.PayloadBank`) filters the measurement
   with the Kalman filter of every grid payload and, while a joint moves, reweighs them (with
   the ``[payload]`` rest levels its control filters slow down once the reference has rested
   for ``rest_delay``: :meth:`PayloadAware._resting`);
2. the design runs at the largest grid payload at or below
   ``max(lightest, mean - err_light_sigmas * std)``: an over-estimated payload is the unstable
   side (a design for 0.25 kg is unstable on the bare arm at some poses), an under-estimated one
   costs only performance;
3. ``u = u_ref,i(t) - K_i (x_hat,i - x_ref,i(t))`` with the bank's filter ``i`` as the state
   estimate and the reference (quasi-static deflection, feed-forward) built on grid model ``i``.

A switch is bumpless by construction: every filter of the bank has run on every sample, so
the new design starts from its own converged estimate, and the torque held carries over.

The grid is designed at the pose the controller is sent to (its reference's target, or the
operating point with no reference), once per pose, when first needed.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from flexctrl.control.controller import Controller
from flexctrl.control.lqr import build_sensors
from flexctrl.control.payload.bank import PayloadBank, PayloadEstimate, RigidCoriolis
from flexctrl.control.payload.grid import PayloadGrid, check_certificate
from flexctrl.control.reference_trajectory import HoldReference, ReferenceTrajectory
from flexctrl.linear import OperatingPoint, torque_limits

#: Joint angles (rad) closer than this count as one pose (one grid).
POSE_TOLERANCE = 1e-6
#: Joint reference rates (rad/s) at or below this count as the reference at rest.
REST_RATE = 1e-9


class PayloadHistory:
    """The estimate at every sample: time (s), mean, std and design payload (kg)."""

    def __init__(self):
        self.rows: list[tuple[float, float, float, float]] = []

    def append(self, t: float, estimate: PayloadEstimate) -> None:
        """Record ``estimate`` at ``t`` (s)."""
        self.rows.append((t, estimate.mean, estimate.std, estimate.design))

    def arrays(self) -> dict[str, np.ndarray]:
        """``time`` (s), ``mean``, ``std``, ``design`` (kg) as arrays."""
        data = np.array(self.rows, dtype=float).reshape(-1, 4)
        return {name: data[:, i].copy() for i, name in enumerate(("time", "mean", "std", "design"))}


class PayloadAware(Controller):
    """What the payload-aware controllers share: the grids per pose, the bank, the estimate.

    Parameters
    ----------
    settings : LQRSettings or MPCSettings
        The recipe with its ``payload`` table.
    model : flexctrl.dynamics.model.Model
        The design model (its payload is replaced by the grid's).
    op : OperatingPoint
        The target without a reference.
    certify : bool
        Compute the grid certificate when a grid is built and warn on a failing cell.
    """

    def __init__(self, settings, model, op: OperatingPoint, *, certify: bool = True):
        limits = torque_limits(model)
        sensors = build_sensors(model, settings.sensors, op)
        super().__init__(
            settings,
            op,
            sensors,
            limits,
            saturate=getattr(settings, "saturate", True),
            design_model=model,
        )
        self.certify = certify
        self._grids: dict[tuple[float, ...], tuple[PayloadGrid, PayloadBank, list]] = {}
        self._references: dict[tuple, Any] = {}
        self._coriolis = (
            RigidCoriolis(model, settings.sample_time) if settings.payload.coriolis else None
        )
        self.index = 0
        self.history = PayloadHistory()
        #: ``(t, payload)`` of every design switch since the last reset.
        self.switches: list[tuple[float, float]] = []
        self._last_moving = -math.inf

    # -- the grid at the current pose -------------------------------------------------------
    def _target(self) -> tuple[float, ...]:
        """The joint angles the controller is sent to, rad."""
        path = getattr(self.reference, "path", None)
        return tuple(float(a) for a in (self.op.joints if path is None else path.q_target))

    def _pose(self) -> tuple[int, ...]:
        """The target as a key (multiples of :data:`POSE_TOLERANCE`)."""
        return tuple(round(a / POSE_TOLERANCE) for a in self._target())

    def _entry(self):
        pose = self._pose()
        entry = self._grids.get(pose)
        if entry is None:
            grid = PayloadGrid(self.design_model, self._target(), self.settings)
            certificate = grid.certificate() if self.certify else []
            check_certificate(certificate)
            joints = [self.sensors.names.index(f"q{j + 1}") for j in range(self.n_u)]
            bank = PayloadBank(grid, self.settings.payload, self._coriolis, joints)
            entry = self._grids[pose] = (grid, bank, certificate)
        return entry

    @property
    def grid(self) -> PayloadGrid:
        """The designs at the current pose (built when first asked for)."""
        return self._entry()[0]

    @property
    def bank(self) -> PayloadBank:
        """The payload estimator at the current pose."""
        return self._entry()[1]

    @property
    def certificate(self) -> list[dict]:
        """The grid certificate at the current pose (:meth:`PayloadGrid.certificate`)."""
        return self._entry()[2]

    @property
    def payload_estimate(self) -> PayloadEstimate:
        """The estimate now: mean and std (kg), the design payload (kg), whether it learned."""
        bank = self.bank
        return PayloadEstimate(
            bank.mean, bank.std, float(self.grid.payloads[self.index]), bank.excited
        )

    def payload_trace(self) -> dict[str, np.ndarray]:
        """The estimate at every sample since the last reset (:meth:`PayloadHistory.arrays`)."""
        return self.history.arrays()

    def _reference_changed(self) -> None:
        """Build the grid at the new target and every design's reference table now.

        The tables (quasi-static deflection, feed-forward) then cost set-up time, not loop time.
        """
        for i in range(len(self._entry()[0].designs)):
            self._reference(i).at(0.0, self.sample_time)

    def _reference(self, i: int):
        """The reference built on grid model ``i`` (the design's feed-forward), kept."""
        reference = self.reference
        if isinstance(reference, HoldReference):
            return HoldReference(self.grid.designs[i].plant.op)
        key = (self._pose(), i, reference.path, reference.deflection)
        built = self._references.get(key)
        if built is None:
            model = self.grid.designs[i].model
            built = ReferenceTrajectory(
                model, reference.path, reference.deflection, compile=reference.compile
            )
            self._references[key] = built
        return built

    def _reset(self) -> None:
        self.bank.reset()
        self.history = PayloadHistory()
        self.switches = []
        self.index = self.grid.index_at_or_below(self.bank.light_side())
        self._last_moving = -math.inf

    def _choose(self, t: float) -> int:
        """The design index for the light side of the estimate; records a switch."""
        i = self.grid.index_at_or_below(self.bank.light_side())
        if i != self.index:
            self.switches.append((t, float(self.grid.payloads[i])))
            self.index = i
            self._last_moving = t  # the new design's filter tracks at moving gains first
        return i

    def _resting(self, t: float) -> bool:
        """Whether the reference's joint rates have been zero for ``rest_delay`` at ``t`` (s)."""
        if not isinstance(self.reference, HoldReference):
            x_ref = self._reference(self.index).at(t, self.sample_time)[0]
            n_q = self.design_model.n_q
            if np.max(np.abs(x_ref[n_q : n_q + self.n_u])) > REST_RATE:
                self._last_moving = t
                return False
        return t - self._last_moving >= self.settings.payload.rest_delay - 1e-9

    def _learn(self, t: float, y: np.ndarray) -> int:
        """Update the bank on ``y``, pick the design, record the estimate; the design index."""
        self.bank.rest(self._resting(t))
        self.bank.update(y, self.u_previous)
        i = self._choose(t)
        self.history.append(t, self.payload_estimate)
        return i

    def _coast(self, t: float) -> int:
        """Predict the bank without a measurement; the design is kept."""
        self.bank.rest(self._resting(t))
        self.bank.predict(self.u_previous)
        self.history.append(t, self.payload_estimate)
        return self.index

    def law_key(self) -> tuple:
        """What :meth:`linear_law` depends on besides the design: the pose and the design in use."""
        return (self._pose(), self.index)

    def linear_law(self, q_joints) -> tuple[np.ndarray, ...]:
        """The LQG of the design in use about the reference at rest (the linear verdict's law).

        ``(E, F, G, H, J)`` (:func:`flexctrl.loop.verdict.linear_closed_loop_radius`): the grid
        design's Kalman filter and ``H = -K``.
        """
        return self.grid.designs[self.index].law


class PayloadLQRController(PayloadAware):
    """The payload-aware LQG (module docstring); built by :func:`design_lqr_payload`.

    Parameters
    ----------
    settings : LQRSettings
        The recipe with its ``payload`` table.
    model : flexctrl.dynamics.model.Model
        The design model (its payload is replaced by the grid's).
    op : OperatingPoint
        The target without a reference.
    certify : bool
        Compute the grid certificate when a grid is built and warn on a failing cell.
    """

    kind = "lqr"

    def _law(self, t: float, i: int) -> np.ndarray:
        x = self.bank.state(i)
        x_ref, u_ref, _ = self._reference(i).at(t, self.sample_time)
        self.record("ok")
        return u_ref - self.grid.K[i] @ (x - x_ref)

    def _step(self, t: float, y: np.ndarray) -> np.ndarray:
        return self._law(t, self._learn(t, y))

    def _hold(self, t: float) -> np.ndarray:
        """Torques without a measurement: the bank predicts, the estimate is not updated."""
        return self._law(t, self._coast(t))


def design_lqr_payload(model, op: OperatingPoint, settings) -> PayloadLQRController:
    """Build the payload-aware LQG of ``settings`` (an :class:`LQRSettings` with ``payload``).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model; its payload is replaced by every grid payload.
    op : OperatingPoint
        The target without a reference.
    settings : LQRSettings
        Weights, sensors, estimator noise and the ``payload`` table.

    Returns
    -------
    PayloadLQRController
    """
    return PayloadLQRController(settings, model, op)


__all__ = [
    "PayloadAware",
    "PayloadLQRController",
    "PayloadHistory",
    "design_lqr_payload",
]
