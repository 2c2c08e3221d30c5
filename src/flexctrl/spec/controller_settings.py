"""Typed, validated settings of every controller (frozen dataclasses).

Each settings class checks its own fields when built (``__post_init__``) and
raises :class:`~flexctrl.errors.SpecError` naming the key, the value and what is
allowed; :func:`flexctrl.spec.controller_reader.load_controller` reads the same classes
from ``controllers/*.toml`` and adds the file name to the message.

Units: SI.  Angles are radians here and degrees in the TOML files (the loader
converts).  Weights follow Bryson's rule: each is the *acceptable magnitude* of
its quantity, ``Q = diag(1 / x_max^2)``, ``R = diag(1 / u_max^2)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

from flexctrl.errors import SpecError, keywords_checked
from flexctrl.spec.controller_shared import (  # noqa: F401  (re-exported)
    BadMeasurement,
    ControllerKind,
    EstimatorSettings,
    Fallback,
    Formulation,
    FrequencySource,
    GravityCompensation,
    NLPSolver,
    NMPCMode,
    PredictionBasis,
    PredictionMap,
    QPBackend,
    RTIQPSolver,
    Scaling,
    Sensitivities,
    SensorSettings,
    Shaper,
    SoftConstraint,
    WarmStart,
    Weights,
)
from flexctrl.spec.field_checks import (
    boolean_field,
    choice_field,
    integer_field,
    number_field,
    numbers_field,
)
from flexctrl.spec.mpc_settings import MPCSettings, NMPCSettings, OSQPSettings
from flexctrl.spec.payload_settings import PayloadSettings
from flexctrl.spec.raw_weights import Matrix, weight_matrix


@dataclass(frozen=True)
class ScheduleSettings:
    """Gain scheduling over configuration: gains designed on a grid and interpolated (multilinear).

    Attributes
    ----------
    joints : tuple of int
        Scheduling joints, 1-based (e.g. ``(2, 3)``).
    grid : tuple of tuple of float
        Grid of joint angles (rad, strictly increasing) per scheduling joint.  The other
        joints stay at the target.  Outside the grid the gains of the nearest edge are used.
    """

    joints: tuple[int, ...] = ()
    grid: tuple[tuple[float, ...], ...] = ()

    def __post_init__(self) -> None:
        if not self.joints:
            raise SpecError(
                "no scheduling joints given; allowed: at least one joint q1..qn with its grid",
                key="joints",
            )
        if len(self.grid) != len(self.joints):
            raise SpecError(
                f"value {self.grid!r} has {len(self.grid)} grids for {len(self.joints)} joints",
                key="grid",
            )
        for j, (joint, values) in enumerate(zip(self.joints, self.grid)):
            integer_field(f"joints[{j}]", joint, low=1)
            numbers_field(f"q{joint}", values)
            if len(values) < 2 or any(b <= a for a, b in zip(values, values[1:])):
                raise SpecError(
                    f"value {[round(math.degrees(v), 6) for v in values]!r} (deg) is not allowed; "
                    "allowed: at least 2 strictly increasing angles",
                    key=f"q{joint}",
                )


# --------------------------------------------------------------------------------------
# controllers
# --------------------------------------------------------------------------------------
@keywords_checked
@dataclass(frozen=True)
class PDSettings:
    """Joint PD control with gravity compensation.

    ``tau = tau_g + tau_ff + F(s) [Kp (q_ref - q) + Kd (qd_ref - qd)]`` (see
    :mod:`flexctrl.control.pd`).

    Attributes
    ----------
    kind : str
        ``"pd"``, the controller this describes (fixed by the class).
    sample_time : float
        s.
    kp, kd : tuple of float
        Gains per joint (N m/rad, N m s/rad); empty: from ``bandwidth`` and ``damping``
        with the joint inertia ``M_ii`` at the target (``kp = M_ii w^2``, ``kd = 2 zeta M_ii w``).
    bandwidth : float
        Hz, for automatic gains.
    damping : float
        Damping ratio of the automatic gains.
    torque_filter : float
        Corner frequency (Hz) of the first-order low-pass on the PD torque; 0: none
        (see :mod:`flexctrl.control.pd` for why light hubs need it).
    gravity : {"target", "measured", "none"}
        Gravity compensation: the static torque of the target equilibrium (with its
        static deflection), ``g`` at the measured joint angles (rigid), or none.
    saturate : bool
        Clip torques at the joint limits.
    feedforward : bool
        Add the inertial feed-forward torque of a moving reference (the rigid inverse
        dynamics along the path); no effect for a step or without a reference.
    strain_rate_gain : tuple of float
        Active damping from the strain gauges, one gain per joint (N m per 1/(m s)): joint
        ``i`` adds ``-g_i d(kappa_i)/dt``, the rate of its own link's root curvature (the
        gauge next to its motor, so the loop stays nearly collocated).  Empty: none.
        Needs ``"strain"`` among the sensors.
    strain_rate_filter : float
        Corner frequency (Hz) of the first-order low-pass on the differentiated strain; 0: none.
    sensors : SensorSettings
        Default: joint encoders and joint rates.
    on_bad_measurement : {"raise", "hold"}
        A measurement with a non-finite entry raises
        :class:`~flexctrl.errors.MeasurementError` and leaves the controller as it was
        (``"raise"``), or the sample is skipped (``"hold"``): PD has no model to predict
        with, so the previous torque is held, the filters keep their state, and the sample
        is counted in ``stats.status["held"]``.  A wrong length always raises.
    """

    kind: Literal["pd"] = "pd"
    sample_time: float = 0.001
    kp: tuple[float, ...] = ()
    kd: tuple[float, ...] = ()
    bandwidth: float = 1.0
    damping: float = 1.0
    torque_filter: float = 2.0
    gravity: GravityCompensation = "target"
    saturate: bool = True
    feedforward: bool = True
    strain_rate_gain: tuple[float, ...] = ()
    strain_rate_filter: float = 0.0
    sensors: SensorSettings = field(
        default_factory=lambda: SensorSettings(outputs=("joints", "joint_rates"))
    )
    on_bad_measurement: BadMeasurement = "raise"

    def __post_init__(self) -> None:
        choice_field("kind", self.kind, Literal["pd"])
        choice_field("on_bad_measurement", self.on_bad_measurement, BadMeasurement)
        number_field("sample_time", self.sample_time, low=0.0, low_open=True, unit="s")
        numbers_field("kp", self.kp, low=0.0)
        numbers_field("kd", self.kd, low=0.0)
        if len(self.kp) != len(self.kd):
            raise SpecError(
                f"value {list(self.kd)!r} has {len(self.kd)} gains but kp has {len(self.kp)}",
                key="kd",
            )
        number_field("bandwidth", self.bandwidth, low=0.0, low_open=True, unit="Hz")
        number_field("damping", self.damping, low=0.0, low_open=True)
        number_field("torque_filter", self.torque_filter, low=0.0, unit="Hz")
        choice_field("gravity", self.gravity, GravityCompensation)
        boolean_field("saturate", self.saturate)
        boolean_field("feedforward", self.feedforward)
        missing = {"joints", "joint_rates"} - set(self.sensors.outputs)
        if missing and not self.sensors.full_state:
            raise SpecError(
                f"value {list(self.sensors.outputs)!r} is not allowed; PD needs 'joints' and "
                "'joint_rates' "
                "(or 'state')",
                key="sensors.outputs",
            )
        numbers_field("strain_rate_gain", self.strain_rate_gain)
        number_field("strain_rate_filter", self.strain_rate_filter, low=0.0, unit="Hz")
        if self.strain_rate_gain and "strain" not in self.sensors.outputs:
            raise SpecError(
                f"value {list(self.strain_rate_gain)!r} needs strain gauges; allowed: 'strain' "
                "among "
                f"sensors.outputs (now {list(self.sensors.outputs)!r})",
                key="strain_rate_gain",
            )


@keywords_checked
@dataclass(frozen=True)
class LQRSettings:
    """Settings of a discrete LQR on the flexible linearization (LQG with a Kalman filter).

    The Kalman filter estimates the state when the sensors do not measure all of it.

    Attributes
    ----------
    kind : str
        ``"lqr"``, the controller this describes (fixed by the class).
    sample_time : float
        s.
    weights : Weights
        Bryson's-rule magnitudes the weights come from, unless ``Q`` / ``R`` are given.
    Q : array_like, optional
        Raw state weight on the design model's state ``(q, qd)`` in SI units (rad, m,
        rad/s, m/s), in the order of ``fc.linearize(model, op).state_labels`` or a designed
        controller's ``state_names``: a square matrix or a list (its diagonal), symmetric
        and positive semidefinite (:mod:`flexctrl.spec.raw_weights`).  Replaces the state
        magnitudes of ``weights``.  Stored as a tuple of rows.
    R : array_like, optional
        Raw torque weight (per (N m)^2), one row per joint, symmetric positive definite;
        replaces ``weights.torque``.
    sensors : SensorSettings
        ``("state",)`` for full-state LQR; e.g. ``("joints", "strain")`` for LQG.
    estimator : EstimatorSettings
        Used when ``sensors`` do not measure the state.
    schedule : ScheduleSettings or None
        Gain scheduling over configuration.
    saturate : bool
        Clip torques at the joint limits.
    on_bad_measurement : {"raise", "hold"}
        A measurement with a non-finite entry raises
        :class:`~flexctrl.errors.MeasurementError` and leaves the controller as it was
        (``"raise"``), or the sample is skipped (``"hold"``): the estimator predicts with the
        torque applied, without a correction, the gain acts on the prediction, and the
        sample is counted in ``stats.status["held"]``.  A wrong length always raises.
    payload : PayloadSettings or None
        A payload range instead of the design model's one payload: the controller is
        payload-aware (:mod:`flexctrl.control.payload`).
    """

    kind: Literal["lqr"] = "lqr"
    sample_time: float = 0.01
    weights: Weights = field(default_factory=Weights)
    sensors: SensorSettings = field(default_factory=SensorSettings)
    estimator: EstimatorSettings = field(default_factory=EstimatorSettings)
    schedule: ScheduleSettings | None = None
    saturate: bool = True
    on_bad_measurement: BadMeasurement = "raise"
    Q: Matrix | None = None
    R: Matrix | None = None
    payload: PayloadSettings | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "Q", weight_matrix("Q", self.Q))
        object.__setattr__(self, "R", weight_matrix("R", self.R))
        choice_field("kind", self.kind, Literal["lqr"])
        number_field("sample_time", self.sample_time, low=0.0, low_open=True, unit="s")
        boolean_field("saturate", self.saturate)
        choice_field("on_bad_measurement", self.on_bad_measurement, BadMeasurement)


@keywords_checked
@dataclass(frozen=True)
class ShapedSettings:
    """Input shaping (ZV/ZVD) of the joint reference, tracked by PD: the open-loop comparison.

    The reference steps (or ramps over ``move_time``) from the joint angles of the
    first measurement after :meth:`reset` to the target, convolved with the shaper.

    Attributes
    ----------
    kind : str
        ``"shaped"``, the controller this describes (fixed by the class).
    shaper : {"zv", "zvd", "none"}
    modes : int
        Number of lowest vibration modes shaped (one shaper per mode, convolved).
    frequency_source : {"closed_loop", "locked"}
        Frequencies and damping from the linearised arm under the PD loop at the target,
        or from the locked-joint structure (:func:`flexctrl.linear.locked_frequencies`, undamped).
    move_time : float
        Duration of the unshaped ramp, s (0: a step).
    pd : PDSettings
        The tracking PD (its ``sample_time`` is the controller's).
    """

    kind: Literal["shaped"] = "shaped"
    shaper: Shaper = "zvd"
    modes: int = 1
    frequency_source: FrequencySource = "closed_loop"
    move_time: float = 0.0
    pd: PDSettings = field(default_factory=PDSettings)

    def __post_init__(self) -> None:
        choice_field("kind", self.kind, Literal["shaped"])
        choice_field("shaper", self.shaper, Shaper)
        integer_field("modes", self.modes, low=1, high=12)
        choice_field("frequency_source", self.frequency_source, FrequencySource)
        number_field("move_time", self.move_time, low=0.0, unit="s")

    @property
    def sample_time(self) -> float:
        """s (the PD's)."""
        return self.pd.sample_time

    @property
    def sensors(self) -> SensorSettings:
        """The PD's sensors."""
        return self.pd.sensors

    @property
    def on_bad_measurement(self) -> str:
        """The PD's ``on_bad_measurement`` (``[pd]`` in a file)."""
        return self.pd.on_bad_measurement


ControllerSettings = PDSettings | LQRSettings | MPCSettings | NMPCSettings | ShapedSettings

#: Settings class per controller kind.
SETTINGS: dict[str, type] = {
    "pd": PDSettings,
    "lqr": LQRSettings,
    "mpc": MPCSettings,
    "nmpc": NMPCSettings,
    "shaped": ShapedSettings,
}

__all__ = [
    "SensorSettings",
    "Weights",
    "EstimatorSettings",
    "ScheduleSettings",
    "PDSettings",
    "LQRSettings",
    "OSQPSettings",
    "MPCSettings",
    "NMPCSettings",
    "ShapedSettings",
    "PayloadSettings",
    "ControllerSettings",
    "SETTINGS",
    "ControllerKind",
]
