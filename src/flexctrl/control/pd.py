"""Joint PD control with gravity compensation and feed-forward: the baseline.

``tau = tau_g(t) + tau_ff(t) + F(s) [Kp (q_ref(t) - q) + Kd (qd_ref(t) - qd)]`` on the joint
coordinates, with ``q_ref``, ``qd_ref`` the joint path of the controller's reference
(:mod:`flexctrl.control.reference_trajectory`; the target itself when none is set; a subclass
may shape it: :class:`~flexctrl.control.shaping.ShapedController`), ``tau_ff`` the
inertial feed-forward ``u_ref - u_static`` of that reference (the rigid inverse
dynamics along the path at the static deflection; zero for a step or no reference;
``feedforward = false`` drops it) and ``tau_g``

* ``"target"``: the static torque of the reference equilibrium ``u_static(t)`` (gravity and
  the static deflection at ``q_ref(t)``: exact at rest there; ``op.u`` with no reference),
* ``"measured"``: the static torque at the measured joint angles, elastic
  coordinates at the target's static deflection,
* ``"none"``.

Automatic gains (``kp``/``kd`` empty): ``kp_i = M_ii w^2``, ``kd_i = 2 zeta M_ii w``
with ``w = 2 pi bandwidth`` and ``M_ii`` the inertia joint ``i`` sees at the target
with the other coordinates held.

Active damping from strain gauges (``strain_rate_gain``, optional): joint ``i`` adds
``-g_i r_i`` with ``r_i`` the rate of its own link's root curvature, differenced over a
sample and low-passed at ``strain_rate_filter`` (Hz; 0: none), outside ``F(s)``.  The root
bending moment of link ``i`` acts on hub ``i`` where its motor acts, so the term stays
close to collocated: it damps the link's vibration without needing its mode shapes,
which change with the payload and the pose.

``F(s)`` is a first-order low-pass of corner ``torque_filter`` (Hz; exact
discretisation, ``f_k = a f_{k-1} + (1 - a) tau_pd,k``, ``a = exp(-2 pi fc dt)``, started
at zero; 0 switches it off).  It is needed on arms whose hubs are light: the torque
first accelerates the hub against the bending links (inertia ``J_hub``), so the sampled
loop sees the gains ``kd dt / J_hub`` and ``kp dt^2 / J_hub``, far beyond the ZOH stability
bound at any practical rate.  Continuous PD is stable for any gains (collocated and
passive); the sampled, unfiltered one is not.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from flexctrl.control.controller import Controller, SampledLaw
from flexctrl.control.lqr import build_sensors
from flexctrl.errors import SpecError
from flexctrl.linear import OperatingPoint, Sensors, stiffness_matrix, torque_limits
from flexctrl.spec.controller_settings import PDSettings


def pd_gains(model, op: OperatingPoint, settings: PDSettings) -> tuple[np.ndarray, np.ndarray]:
    """``(kp, kd)`` per joint, explicit from the settings or automatic (module docstring).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model (its mass matrix gives the automatic gains).
    op : OperatingPoint
        The target.
    settings : PDSettings
        Explicit gains, or the bandwidth (Hz) and damping ratio of the automatic ones.

    Returns
    -------
    tuple of ndarray
        ``kp`` (N m/rad) and ``kd`` (N m s/rad), one per joint.

    Raises
    ------
    SpecError
        When explicit gains are not one per joint.
    """
    n = model.n_u
    if settings.kp:
        if len(settings.kp) != n:
            raise SpecError(
                f"value {list(settings.kp)!r} has {len(settings.kp)} gains; expected {n} (one "
                "per joint)",
                key="kp",
            )
        return np.asarray(settings.kp, dtype=float), np.asarray(settings.kd, dtype=float)
    inertia = np.diag(model.mass_matrix(op.q))[:n]
    w = 2 * math.pi * settings.bandwidth
    return inertia * w**2, 2 * settings.damping * inertia * w


def static_torque_function(model, q_flex: np.ndarray) -> ca.Function:
    """``(qr) -> tau``: joint rows of ``g(q) + K q``, the elastic coordinates held at ``q_flex``.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        Its ``g`` and stiffness.
    q_flex : ndarray
        The elastic coordinates (the target's static deflection).

    Returns
    -------
    casadi.Function
        Joint angles (rad) to the static joint torques (N m).
    """
    qr = ca.SX.sym("qr", model.n_u)
    q = ca.vertcat(qr, ca.DM(np.asarray(q_flex, dtype=float)))
    static = model.functions["g"](q) + ca.mtimes(stiffness_matrix(model, q), q)
    return ca.Function("static_torque", [qr], [static[: model.n_u]])


class PDController(Controller):
    """PD on the joints with gravity compensation (see the module docstring).

    Built by :func:`design_pd` (through :func:`flexctrl.design`).

    Parameters
    ----------
    settings : PDSettings
        Sample time, bandwidth, damping, torque filter, gravity compensation, sensors.
    op : OperatingPoint
        The target equilibrium.
    sensors : Sensors
        Joint encoders (and rates).
    limits : ndarray
        Torque limits per joint, N m.
    kp, kd : ndarray
        Proportional (N m/rad) and derivative (N m s/rad) gains per joint.
    gravity : casadi.Function or None
        The gravity torque compensated, or None.
    design_model : Model, optional
        The model designed on (:class:`~flexctrl.control.controller.Controller`).
    """

    kind = "pd"

    def __init__(
        self,
        settings: PDSettings,
        op: OperatingPoint,
        sensors: Sensors,
        limits: np.ndarray,
        kp: np.ndarray,
        kd: np.ndarray,
        gravity: ca.Function | None,
        *,
        design_model=None,
    ):
        super().__init__(
            settings, op, sensors, limits, saturate=settings.saturate, design_model=design_model
        )
        self.pd_settings = settings
        self.kp, self.kd = kp, kd
        self.gravity = gravity
        self.gravity_mode = settings.gravity
        fc = settings.torque_filter
        self.filter_pole = math.exp(-2 * math.pi * fc * settings.sample_time) if fc > 0 else 0.0
        self._filtered = np.zeros(self.n_u)
        n = self.n_u
        names = sensors.names
        if sensors.full_state:
            N = op.n_q
            self._iq, self._iqd = np.arange(n), N + np.arange(n)
        else:
            self._iq = np.array([names.index(f"q{i + 1}") for i in range(n)])
            self._iqd = np.array([names.index(f"dq{i + 1}") for i in range(n)])
        self.strain_gain = np.zeros(0)
        gains = getattr(settings, "strain_rate_gain", ())
        if gains:
            if len(gains) != n:
                raise SpecError(
                    f"value {list(gains)!r} has {len(gains)} gains; expected {n} (one per joint)",
                    key="strain_rate_gain",
                )
            missing = [f"kappa{i + 1}" for i in range(n) if f"kappa{i + 1}" not in names]
            if missing:
                raise SpecError(
                    f"the sensors give no {', '.join(missing)} (links without modes have no strain "
                    "gauge); allowed: strain_rate_gain only on a flexible model",
                    key="strain_rate_gain",
                )
            self.strain_gain = np.asarray(gains, dtype=float)
            self._ik = np.array([names.index(f"kappa{i + 1}") for i in range(n)])
            corner = settings.strain_rate_filter
            self.strain_pole = (
                math.exp(-2 * math.pi * corner * settings.sample_time) if corner > 0 else 0.0
            )
        self._kappa: np.ndarray | None = None
        self._rate = np.zeros(n)

    def _reset(self) -> None:
        self._filtered = np.zeros(self.n_u)
        self._kappa = None
        self._rate = np.zeros(self.n_u)

    def _strain_damping(self, y: np.ndarray) -> np.ndarray | float:
        """``-g r``, ``r`` the filtered rate of the root curvatures (zero at the first sample)."""
        if not self.strain_gain.size:
            return 0.0
        kappa = y[self._ik]
        raw = (
            np.zeros(self.n_u) if self._kappa is None else (kappa - self._kappa) / self.sample_time
        )
        self._kappa = kappa
        b = self.strain_pole
        self._rate = b * self._rate + (1.0 - b) * raw
        return -self.strain_gain * self._rate

    def linear_law(self, q_joints) -> tuple[np.ndarray, ...]:
        """The law about the reference at rest at ``q_joints`` (rad), for the linear verdict.

        ``(E, F, G, H, J)`` of ``xi_k = E xi_{k-1} + F dy_k + G du_{k-1}``,
        ``du_k = H xi_k + J dy_k`` (:func:`flexctrl.loop.verdict.linear_closed_loop_radius`):
        ``xi`` is the filtered PD torque, ``E = a I``, ``F = -(1 - a) (Kp S_q + Kd S_qd)``;
        measured gravity compensation adds its Jacobian through ``J``.
        """
        n, n_y = self.n_u, self.sensors.n_y
        Sq, Sqd = np.zeros((n, n_y)), np.zeros((n, n_y))
        Sq[np.arange(n), self._iq] = 1.0
        Sqd[np.arange(n), self._iqd] = 1.0
        a = self.filter_pole
        F = -(1.0 - a) * (np.diag(self.kp) @ Sq + np.diag(self.kd) @ Sqd)
        J = np.zeros((n, n_y))
        if self.gravity_mode == "measured" and self.gravity is not None:
            qr = ca.SX.sym("qr", n)
            jac = ca.Function("dtau_g", [qr], [ca.jacobian(self.gravity(qr), qr)])
            J = np.array(jac(np.asarray(q_joints, dtype=float)), dtype=float) @ Sq
        if not self.strain_gain.size:
            return a * np.eye(n), F, np.zeros((n, n)), np.eye(n), J
        # memory (filtered torque, last curvatures, filtered curvature rate):
        # kappa_k = Sk dy_k, r_k = b r_{k-1} + (1 - b) (kappa_k - kappa_{k-1}) / Ts,
        # du = f - g r + J dy
        Sk = np.zeros((n, n_y))
        Sk[np.arange(n), self._ik] = 1.0
        b, Ts, Z, I = self.strain_pole, self.sample_time, np.zeros((n, n)), np.eye(n)
        E = np.block([[a * I, Z, Z], [Z, Z, Z], [Z, -(1.0 - b) / Ts * I, b * I]])
        F3 = np.vstack([F, Sk, (1.0 - b) / Ts * Sk])
        H = np.hstack([I, Z, -np.diag(self.strain_gain)])
        return E, F3, np.zeros((3 * n, n)), H, J

    def reference_terms(
        self, t: float, q: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(q_ref, qd_ref, u_ref, u_static)`` at time ``t`` (s); ``q`` are the measured joints.

        From the reference's table on the sample grid with the static deflection
        (``elastic=False``: PD has no use for the elastic reference).
        """
        x, u_ref, u_static = self.reference.at(t, self.sample_time, elastic=False)
        N = x.size // 2
        return x[: self.n_u], x[N : N + self.n_u], u_ref, u_static

    def reference_table(self, times: np.ndarray) -> np.ndarray:
        """Rows ``(q_ref, qd_ref, u_ref, u_static)`` of :meth:`reference_terms` at ``times``.

        ``times`` are sample times (s) from now on.
        """
        X, U, Us = self.reference.window(
            float(times[0]), self.sample_time, len(times), elastic=False
        )
        N = X.shape[1] // 2
        return np.hstack([X[:, : self.n_u], X[:, N : N + self.n_u], U, Us])

    def has_sampled_law(self) -> bool:
        """True: the PD law and its filters are one CasADi map (:meth:`sampled_law`)."""
        return True

    def sampled_law(self) -> SampledLaw:
        """:meth:`_step` as one CasADi map (:class:`SampledLaw`), the same operations in order.

        Memory: the filtered PD torque, then (with strain-rate damping) the last root
        curvatures and their filtered rate.  Reference rows: :meth:`reference_table`.
        """
        n = self.n_u
        strain = bool(self.strain_gain.size)
        memory = np.concatenate([self._filtered] + ([self._kappa, self._rate] if strain else []))
        xi, y = ca.MX.sym("xi", memory.size), ca.MX.sym("y", self.sensors.n_y)
        u_prev, r = ca.MX.sym("u_prev", n), ca.MX.sym("r", 4 * n)
        q, qd = y[self._iq.tolist()], y[self._iqd.tolist()]
        q_ref, qd_ref, u_ref, u_static = (r[i * n : (i + 1) * n] for i in range(4))
        tau_g = {
            "target": u_static,
            "measured": self.gravity(q) if self.gravity is not None else 0.0,
        }.get(self.gravity_mode, 0.0)
        tau_ff = u_ref - u_static if self.pd_settings.feedforward else 0.0
        a = self.filter_pole
        filtered = a * xi[:n] + (1.0 - a) * (
            ca.DM(self.kp) * (q_ref - q) + ca.DM(self.kd) * (qd_ref - qd)
        )
        u = tau_g + tau_ff + filtered
        parts = [filtered]
        if strain:
            kappa = y[self._ik.tolist()]
            b = self.strain_pole
            rate = b * xi[2 * n :] + (1.0 - b) * ((kappa - xi[n : 2 * n]) / self.sample_time)
            u = u + (-ca.DM(self.strain_gain)) * rate
            parts += [kappa, rate]
        function = ca.Function(
            f"{self.kind}_law",
            [xi, y, u_prev, r],
            [ca.vertcat(*parts), u],
            ["xi", "y", "u_prev", "r"],
            ["xi_next", "u"],
        )

        def restore(values: np.ndarray) -> None:
            values = np.array(values, dtype=float)
            self._filtered = values[:n]
            if strain:
                self._kappa, self._rate = values[n : 2 * n], values[2 * n :]

        return SampledLaw(function, memory, self.reference_table, restore)

    def _hold(self, t: float) -> np.ndarray | None:
        """The previous torque: PD has no model to predict with; its filters keep their state.

        None before the first sample since :meth:`reset` (no torque of its own to hold).
        """
        return self.u_previous.copy() if self.stats.step_times else None

    def _step(self, t: float, y: np.ndarray) -> np.ndarray:
        q, qd = y[self._iq], y[self._iqd]
        q_ref, qd_ref, u_ref, u_static = self.reference_terms(t, q)
        tau_g: np.ndarray | float
        if self.gravity_mode == "target":
            tau_g = u_static
        elif self.gravity_mode == "measured" and self.gravity is not None:
            tau_g = np.asarray(self.gravity(q), dtype=float).ravel()
        else:
            tau_g = 0.0
        tau_ff = u_ref - u_static if self.pd_settings.feedforward else 0.0
        self.record("ok")
        a = self.filter_pole
        self._filtered = a * self._filtered + (1.0 - a) * (
            self.kp * (q_ref - q) + self.kd * (qd_ref - qd)
        )
        return tau_g + tau_ff + self._filtered + self._strain_damping(y)


def pd_parts(model, op: OperatingPoint, settings: PDSettings):
    """Sensors, limits, gains and gravity Function shared by PD and the shaped controller.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model.
    op : OperatingPoint
        The target.
    settings : PDSettings
        The PD's settings.

    Returns
    -------
    tuple
        ``(sensors, limits (N m), kp, kd, gravity)``: the arguments of :class:`PDController`
        after the settings and the target.
    """
    sensors = build_sensors(model, settings.sensors, op)
    kp, kd = pd_gains(model, op, settings)
    gravity = (
        static_torque_function(model, op.q[model.n_u :]) if settings.gravity == "measured" else None
    )
    return sensors, torque_limits(model), kp, kd, gravity


def design_pd(model, op: OperatingPoint, settings: PDSettings) -> PDController:
    """Build the PD controller holding ``model`` at ``op``.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model.
    op : OperatingPoint
        The target.
    settings : PDSettings
        The PD's settings.

    Returns
    -------
    PDController
    """
    return PDController(settings, op, *pd_parts(model, op, settings), design_model=model)


__all__ = ["PDController", "design_pd", "pd_gains", "static_torque_function", "pd_parts"]
