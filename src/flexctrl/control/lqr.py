"""Discrete LQR on the flexible linearisation, LQG with a Kalman filter, and gain scheduling.

Design (:func:`design_lqr`): linearise the model at the design equilibrium ``op``
with the controller's sensors as outputs, discretise by zero-order hold at the
sample time, weight by Bryson's rule (:func:`weight_matrices`) or the raw ``Q``, ``R`` of the
settings (:func:`design_weights`) and solve the DARE
(by doubling, :mod:`flexctrl.control.riccati`).  Control law, in deviations from the
reference (:mod:`flexctrl.control.reference_trajectory`)::

    u = u_ref(t) - K(s) (x_hat - x_ref(t))

with ``x_hat`` the measured state (sensors ``"state"``) or the Kalman estimate
(:mod:`flexctrl.control.estimator`: LQG), ``x_ref`` the reference state (joint path,
quasi-static deflection and their rates) and ``u_ref`` its feed-forward torque; with
no reference set, ``x_ref = x_op`` and ``u_ref = u_op``.  With a schedule, ``K(s)`` is interpolated
multilinearly in the scheduling joint angles ``s`` (taken from ``x_hat``) between gains
designed at the equilibria on a grid (the other joints at the design point); the
estimator stays that of the design point and the feed-forward is the reference's.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import control
import numpy as np

from flexctrl.control.controller import Controller, SampledLaw
from flexctrl.control.estimator import make_observer
from flexctrl.control.gain_schedule import GainSchedule, gain_schedule
from flexctrl.control.riccati import lqr_gain
from flexctrl.errors import SpecError
from flexctrl.linear import (
    Linearizer,
    OperatingPoint,
    Sensors,
    discretize,
    state_names,
    torque_limits,
)
from flexctrl.spec.controller_settings import (
    LQRSettings,
    SensorSettings,
    Weights,
)
from flexctrl.spec.raw_weights import checked_size


@dataclass(frozen=True, eq=False)
class LinearPlant:
    """The linearization at ``op`` with the controller's sensors, continuous and ZOH-sampled.

    Attributes
    ----------
    sys, sysd : control.StateSpace
        Continuous and discrete (sample time ``dt``) systems in deviation variables.
    op : OperatingPoint
        The operating point linearized at.
    sensors : Sensors
        The outputs of ``sys`` and ``sysd``.
    """

    sys: control.StateSpace
    sysd: control.StateSpace
    op: OperatingPoint
    sensors: Sensors

    @property
    def dt(self) -> float:
        """Sample time, s."""
        return float(self.sysd.dt)

    @property
    def Ad(self) -> np.ndarray:
        """The discrete state matrix."""
        return np.asarray(self.sysd.A, dtype=float)

    @property
    def Bd(self) -> np.ndarray:
        """The discrete input matrix (per N m)."""
        return np.asarray(self.sysd.B, dtype=float)


def build_sensors(model, settings: SensorSettings, op: OperatingPoint) -> Sensors:
    """The :class:`~flexctrl.linear.Sensors` described by ``settings``.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The model the sensors read.
    settings : SensorSettings
        Sensor kinds and noise levels.
    op : OperatingPoint
        The target (the joint angles the strain gauges' map is taken at).

    Returns
    -------
    Sensors

    Raises
    ------
    SpecError
        For a sensor the model cannot give, named under the key ``sensors.outputs``.
    """
    try:
        return Sensors.build(model, settings.outputs, settings.noise(), q_joints=op.joints)
    except SpecError as exc:
        raise SpecError(str(exc).split(": ", 1)[-1], key="sensors.outputs") from None


def linear_plant(
    model, op: OperatingPoint, sensors: Sensors, dt: float, linearizer: Linearizer | None = None
) -> LinearPlant:
    """Linearize at ``op`` with ``sensors`` and discretize at ``dt``.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The model.
    op : OperatingPoint
        Where to linearize.
    sensors : Sensors
        The outputs.
    dt : float
        The sample time, s.
    linearizer : Linearizer, optional
        One already built for ``model`` and ``sensors`` (default: built here).

    Returns
    -------
    LinearPlant
    """
    lin = linearizer or Linearizer(model, sensors)
    sys = lin(op)
    return LinearPlant(sys, discretize(sys, dt), op, sensors)


def weight_matrices(
    model, weights: Weights, limits: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Bryson's-rule ``Q`` (2N x 2N) and ``R`` (n x n) from acceptable magnitudes.

    Torque magnitudes are ``weights.torque`` times the joint torque limits (1 N m where
    there is no limit).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        Its joints and elastic coordinates.
    weights : Weights
        The acceptable magnitudes (rad, rad/s, and the modal coordinates' units).
    limits : ndarray, optional
        Torque limits per joint, N m (default: the model's).

    Returns
    -------
    tuple of ndarray
        ``Q`` and ``R``.
    """
    n, N = model.n_u, model.n_q
    limits = torque_limits(model) if limits is None else np.asarray(limits, dtype=float)
    scale = np.where(np.isfinite(limits), limits, 1.0)
    xmax = np.r_[
        np.full(n, weights.joint),
        np.full(N - n, weights.modal),
        np.full(n, weights.joint_rate),
        np.full(N - n, weights.modal_rate),
    ]
    return np.diag(1.0 / xmax**2), np.diag(1.0 / (weights.torque * scale) ** 2)


def design_weights(
    model, settings, limits: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The ``Q`` (2N x 2N) and ``R`` (n x n) a controller designs with.

    The raw matrices of the settings (``settings.Q``, ``settings.R``) where given, on the
    design model's state in the order of :func:`flexctrl.linear.state_names` (what
    ``fc.linearize(model, op).state_labels`` and a controller's ``state_names`` list), else
    Bryson's rule from ``settings.weights`` (:func:`weight_matrices`).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model.
    settings : LQRSettings or MPCSettings or NMPCSettings
        Its ``weights`` and, where the settings have them, ``Q`` and ``R``.
    limits : ndarray, optional
        Torque limits per joint, N m (default: the model's).

    Returns
    -------
    tuple of ndarray
        ``Q`` and ``R``.

    Raises
    ------
    SpecError
        When a raw matrix does not fit the model, naming ``Q`` or ``R``, its shape and
        the expected one.
    """
    Q, R = weight_matrices(model, settings.weights, limits)
    raw_Q, raw_R = getattr(settings, "Q", None), getattr(settings, "R", None)
    if raw_Q is not None:
        names = ", ".join(state_names(model))
        Q = checked_size("Q", raw_Q, model.n_x, f"states ({names})")
    if raw_R is not None:
        R = checked_size("R", raw_R, model.n_u, f"joint torques (one row per joint, {model.n_u})")
    return Q, R


class LQRController(Controller):
    """``u = u_ref - K (x_hat - x_ref)``; see the module docstring.

    Built by :func:`design_lqr` (through :func:`flexctrl.design`).

    Parameters
    ----------
    settings : LQRSettings
        Sample time, weights, sensors, estimator and schedule.
    plant : LinearPlant
        The linearization at the design point with the controller's sensors, continuous and
        discretized.
    limits : ndarray
        Torque limits per joint, N m.
    K : ndarray
        The gain (n_u x n_x) at the design point.
    S : ndarray
        The discrete Riccati equation's solution.
    observer
        The state estimator (full state or a Kalman filter, :mod:`flexctrl.control.estimator`).
    schedule : GainSchedule, optional
        Gains interpolated in scheduling joint angles instead of ``K``.
    design_model : Model, optional
        The model designed on (:class:`~flexctrl.control.controller.Controller`).
    """

    kind = "lqr"

    def __init__(
        self,
        settings: LQRSettings,
        plant: LinearPlant,
        limits: np.ndarray,
        K: np.ndarray,
        S: np.ndarray,
        observer,
        schedule: GainSchedule | None = None,
        *,
        design_model=None,
    ):
        super().__init__(
            settings,
            plant.op,
            plant.sensors,
            limits,
            saturate=settings.saturate,
            design_model=design_model,
        )
        self.plant = plant
        self.K = K
        self.S = S
        self.observer = observer
        self.schedule = schedule
        #: The state the gain acts on, in order (``Q``'s rows): joints, elastic coordinates, rates.
        self.state_names = tuple(plant.sys.state_labels)

    def gain(self, x: np.ndarray) -> np.ndarray:
        """The gain at state ``x`` (scheduled or fixed)."""
        return self.K if self.schedule is None else self.schedule(x)

    def linear_law(self, q_joints) -> tuple[np.ndarray, ...]:
        """The law about the reference at rest at ``q_joints`` (rad), for the linear verdict.

        ``(E, F, G, H, J)`` of ``xi_k = E xi_{k-1} + F dy_k + G du_{k-1}``, ``du_k = H xi_k + J
        dy_k`` (:func:`flexctrl.loop.verdict.linear_closed_loop_radius`): ``xi`` is the state
        estimate and ``H = -K`` (the scheduled gain at ``q_joints``).
        """
        x = np.array(self.op.x, dtype=float)
        x[: self.n_u] = np.asarray(q_joints, dtype=float)
        E, F, G = self.observer.linear_form(self.sensors.n_y, self.n_u)
        return E, F, G, -self.gain(x), np.zeros((self.n_u, self.sensors.n_y))

    @property
    def closed_loop_poles(self) -> np.ndarray:
        """Eigenvalues of ``A_d - B_d K`` at the target."""
        return np.linalg.eigvals(self.plant.Ad - self.plant.Bd @ self.K)

    def _reset(self) -> None:
        self.observer.reset()

    def has_sampled_law(self) -> bool:
        """True unless the gains are scheduled (see :meth:`sampled_law`)."""
        return self.schedule is None

    def sampled_law(self) -> SampledLaw | None:
        """The law and its estimator as one CasADi map (None with a gain schedule); see
        :class:`SampledLaw`.

        Reference rows ``r = (x_ref, u_ref)``; memory the estimator's (the Kalman
        deviation estimate, nothing for full-state sensors).
        """
        if self.schedule is not None:
            return None

        def references(times: np.ndarray) -> np.ndarray:
            X, U, _ = self.reference.window(float(times[0]), self.sample_time, len(times))
            return np.hstack([X, U])

        return SampledLaw(
            self.law_function(), self.observer.memory, references, self.observer.restore
        )

    def law_function(self, *, start: bool = False) -> ca.Function:
        """The law with its estimator as one CasADi Function (the function of :meth:`sampled_law`).

        Parameters
        ----------
        start : bool
            The first sample after :meth:`reset`, where the estimator starts from the
            measurement: ``(y, u_prev, r) -> (xi, u)``.  False: a later sample,
            ``(xi, y, u_prev, r) -> (xi_next, u)``.

        Returns
        -------
        casadi.Function
            ``xi`` the estimator's memory, ``r = (x_ref, u_ref)`` the reference row; ``u``
            (N m) before clipping.

        Raises
        ------
        SpecError
            For a gain-scheduled LQR (its gain is interpolated per sample).
        """
        if self.schedule is not None:
            raise SpecError(
                "a gain-scheduled LQR has no fixed law; allowed: an LQR without a schedule",
                key="schedule",
            )
        n_x = self.op.x.size
        y, u_prev = ca.MX.sym("y", self.sensors.n_y), ca.MX.sym("u_prev", self.n_u)
        r = ca.MX.sym("r", n_x + self.n_u)
        xi_start, x_start = self.observer.symbolic_start(y, u_prev)
        if start:
            xi_next, x, inputs, names = xi_start, x_start, [y, u_prev, r], ["y", "u_prev", "r"]
        else:
            xi = ca.MX.sym("xi", xi_start.shape[0])
            xi_next, x = self.observer.symbolic(xi, y, u_prev)
            inputs, names = [xi, y, u_prev, r], ["xi", "y", "u_prev", "r"]
        u = r[n_x:] - ca.mtimes(ca.DM(self.K), x - r[:n_x])
        name, first = ("lqr_law_start", "xi") if start else ("lqr_law", "xi_next")
        return ca.Function(name, inputs, [xi_next, u], names, [first, "u"])

    def export_c(self, out, *, replay=None, qp_eps: float | None = None):
        """The law in C (:meth:`Controller.export_c`; :mod:`flexctrl.control.cexport.law`)."""
        from flexctrl.control.cexport.law import export_law

        return export_law(self, out, replay, qp_eps)

    def _step(self, t: float, y: np.ndarray) -> np.ndarray:
        return self._law(t, self.observer.estimate(y, self.u_previous))

    def _hold(self, t: float) -> np.ndarray | None:
        x = self.observer.predict(self.u_previous)
        return None if x is None else self._law(t, x)

    def _law(self, t: float, x: np.ndarray) -> np.ndarray:
        """``u_ref - K (x - x_ref)`` at ``t`` (s) on the state (estimate) ``x``."""
        x_ref, u_ref, _ = self.reference.at(t, self.sample_time)
        self.record("ok")
        return u_ref - self.gain(x) @ (x - x_ref)


def design_lqr(model, op: OperatingPoint, settings: LQRSettings) -> LQRController:
    """Build the (scheduled) LQR or LQG controller regulating ``model`` to ``op``.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model.
    op : OperatingPoint
        The target equilibrium.
    settings : LQRSettings
        Weights, sensors (LQG with a Kalman filter unless the whole state is measured),
        estimator and schedule.

    Returns
    -------
    LQRController
    """
    limits = torque_limits(model)
    sensors = build_sensors(model, settings.sensors, op)
    lin = Linearizer(model, sensors)
    plant = linear_plant(model, op, sensors, settings.sample_time, lin)
    Q, R = design_weights(model, settings, limits)
    K, S = lqr_gain(plant.Ad, plant.Bd, Q, R)
    observer = make_observer(model, op, sensors, plant.sys.A, plant.sysd, settings.estimator)
    schedule = (
        None
        if settings.schedule is None
        else gain_schedule(model, op, settings.schedule, settings.sample_time, Q, R, K.shape)
    )
    return LQRController(settings, plant, limits, K, S, observer, schedule, design_model=model)


__all__ = [
    "LQRController",
    "LinearPlant",
    "design_lqr",
    "linear_plant",
    "weight_matrices",
    "design_weights",
    "lqr_gain",
    "build_sensors",
]
