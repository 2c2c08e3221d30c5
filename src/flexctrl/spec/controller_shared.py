"""Shared pieces of the controller settings: the allowed choices, sensors, weights and estimator.

Re-exported by :mod:`flexctrl.spec.controller_settings` (the one place to import them from);
split off so that no module passes 600 lines.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Literal

from flexctrl.errors import SpecError, keywords_checked
from flexctrl.spec.field_checks import choice_field, number_field
from flexctrl.spec.sensors import DEFAULT_NOISE, SENSOR_KINDS, SensorKind

ControllerKind = Literal["pd", "lqr", "mpc", "nmpc", "shaped"]
GravityCompensation = Literal["target", "measured", "none"]
SoftConstraint = Literal["none", "deflection", "tip"]
Formulation = Literal["sparse", "condensed"]
QPBackend = Literal["osqp", "hpipm", "daqp", "qpoases"]
Scaling = Literal["auto", "bryson", "none"]
WarmStart = Literal["shift", "previous", "none"]
Fallback = Literal["shift", "lqr", "hold"]
NMPCMode = Literal["rti", "full"]
NLPSolver = Literal["ipopt"]
PredictionMap = Literal["modal", "select"]
PredictionBasis = Literal["assumed", "coupled"]
RTIQPSolver = Literal["hpipm", "osqp", "qpoases"]
Sensitivities = Literal["frozen", "midpoint", "exact"]
Shaper = Literal["zv", "zvd", "none"]
FrequencySource = Literal["closed_loop", "locked"]
#: What a controller does with a measurement that is not finite: raise
#: :class:`~flexctrl.errors.MeasurementError`, or skip the sample (prediction only).
BadMeasurement = Literal["raise", "hold"]


# --------------------------------------------------------------------------------------
# shared pieces
# --------------------------------------------------------------------------------------
@keywords_checked
@dataclass(frozen=True)
class SensorSettings:
    """What the controller measures and the noise standard deviation of each sensor.

    Attributes
    ----------
    outputs : tuple of str
        Sensor kinds (:data:`flexctrl.linear.SENSOR_KINDS`): ``"joints"`` (encoders, rad),
        ``"joint_rates"`` (rad/s), ``"strain"`` (root curvature of each flexible link, 1/m),
        ``"tip"`` (m), ``"tip_acc"`` (m/s^2), ``"deflection"`` (link tip deflections, m),
        ``"state"`` (the whole state: no estimator).
    joints, joint_rates, strain, tip, tip_acc, deflection : float
        Noise standard deviations in the unit of the output (>= 0).  The Kalman filter
        uses them as its measurement noise; a closed loop may use them to add noise.
    """

    outputs: tuple[str, ...] = ("state",)
    joints: float = DEFAULT_NOISE["joints"]
    joint_rates: float = DEFAULT_NOISE["joint_rates"]
    strain: float = DEFAULT_NOISE["strain"]
    tip: float = DEFAULT_NOISE["tip"]
    tip_acc: float = DEFAULT_NOISE["tip_acc"]
    deflection: float = DEFAULT_NOISE["deflection"]

    def __post_init__(self) -> None:
        if not isinstance(self.outputs, tuple) or not self.outputs:
            raise SpecError(
                f"value {self.outputs!r} is not allowed; allowed: a non-empty list of "
                f"{', '.join(map(repr, SENSOR_KINDS))}",
                key="outputs",
            )
        for i, kind in enumerate(self.outputs):
            if kind not in SENSOR_KINDS:
                choice_field(f"outputs[{i}]", kind, SensorKind)
        if len(set(self.outputs)) != len(self.outputs):
            raise SpecError(f"value {list(self.outputs)!r} names a sensor twice", key="outputs")
        if "state" in self.outputs and len(self.outputs) > 1:
            raise SpecError(
                f"value {list(self.outputs)!r} is not allowed; 'state' measures everything and "
                "stands alone",
                key="outputs",
            )
        for name in ("joints", "joint_rates", "strain", "tip", "tip_acc", "deflection"):
            number_field(name, getattr(self, name), low=0.0)

    def noise(self) -> dict[str, float]:
        """Noise standard deviation per sensor kind."""
        return {
            name: getattr(self, name)
            for name in ("joints", "joint_rates", "strain", "tip", "tip_acc", "deflection")
        }

    @property
    def full_state(self) -> bool:
        """Whether the whole state is measured."""
        return self.outputs == ("state",)


@keywords_checked
@dataclass(frozen=True)
class Weights:
    """LQR/MPC weights as acceptable magnitudes (Bryson's rule), in the units of each quantity.

    Attributes
    ----------
    joint : float
        Joint-angle error, rad.
    modal : float
        Elastic coordinate, m (modal coordinates are in metres of mass-normalised shapes).
    joint_rate : float
        Joint rate, rad/s.
    modal_rate : float
        Elastic rate, m/s.
    torque : float
        Torque deviation as a fraction of each joint's torque limit (of 1 N m when the
        model has no limits).

    In controller files the angle weights are ``joint_deg`` (deg) and
    ``joint_rate_deg_s`` (deg/s): one name, one unit.
    """

    joint: float = 0.01
    modal: float = 0.002
    joint_rate: float = 0.5
    modal_rate: float = 0.5
    torque: float = 0.5

    def __post_init__(self) -> None:
        for f in fields(self):
            number_field(f.name, getattr(self, f.name), low=0.0, low_open=True)


@keywords_checked
@dataclass(frozen=True)
class EstimatorSettings:
    """Steady-state discrete Kalman filter on the linearisation at the target.

    Used whenever the sensors do not measure the whole state.

    Attributes
    ----------
    kind : str
        ``"kalman"``, the estimator this describes.
    torque_noise : float
        Standard deviation of an unmeasured torque disturbance on each joint, N m
        (held over a sample).
    modal_force_noise : float
        Standard deviation of a generalised-force disturbance on each elastic
        coordinate, N (model error in the elastic dynamics).
    """

    kind: Literal["kalman"] = "kalman"
    torque_noise: float = 2.0
    modal_force_noise: float = 1.0

    def __post_init__(self) -> None:
        choice_field("kind", self.kind, Literal["kalman"])
        number_field("torque_noise", self.torque_noise, low=0.0)
        number_field("modal_force_noise", self.modal_force_noise, low=0.0)


__all__ = ["SensorSettings", "Weights", "EstimatorSettings"]
