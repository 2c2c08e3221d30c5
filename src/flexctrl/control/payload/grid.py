"""The designs at the payloads of a grid, at one pose: the payload-aware controllers' lookup table.

For every grid payload ``m_i`` the design model is rebuilt carrying ``m_i`` (same arm,
fidelity and frozen-mode configuration), linearised at the target with the controller's
sensors, discretised by zero-order hold at the sample time and designed by the controller
file's recipe: the LQR gain ``K_i`` (Bryson weights, DARE) and the steady-state Kalman
filter ``M_i`` with its a-priori covariance ``P_i`` (:mod:`flexctrl.control.estimator`).
The same table feeds the controller (the design it runs) and the payload bank
(:mod:`flexctrl.control.payload.bank`: ``A_i, B_i, C_i, D_i, M_i`` and the innovation
covariance ``S_i = C_i P_i C_i' + R``).

The certificate (:meth:`PayloadGrid.certificate`): the controllers run the design at the
grid payload at or below the estimate's light side, so the design at ``m_i`` must hold the
plants between ``m_i`` and ``m_{i+1}``; the linear verdict (closed-loop spectral radius, the
design's law on the plant's own linearisation) is computed at ``m_i``, at the midpoint and at
``m_{i+1}``.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from flexctrl.control.estimator import make_observer
from flexctrl.control.lqr import build_sensors, linear_plant, weight_matrices
from flexctrl.control.riccati import lqr_gain
from flexctrl.dynamics.build import build_model
from flexctrl.errors import SpecError
from flexctrl.linear import Linearizer, equilibrium, torque_limits
from flexctrl.spec.controller_shared import EstimatorSettings

#: A design whose certificate radius reaches this is flagged (the grid is too coarse there).
CERTIFICATE_LIMIT = 1.0
#: Fraction of a grid step below a grid payload that still designs at it (index_at_or_below).
SNAP = 0.02


@dataclass(frozen=True, eq=False)
class PointDesign:
    """The design at one grid payload.

    Attributes
    ----------
    payload : float
        kg.
    model : Model
        The design model rebuilt carrying ``payload``.
    plant : LinearPlant
        Its linearisation at the target with the controller's sensors (continuous, sampled).
    K : ndarray
        LQR gain (n_u x n_x).
    S : ndarray
        The control DARE's solution.
    observer : KalmanEstimator
        The steady-state Kalman filter of the design while the reference moves.
    rest_observer : KalmanEstimator or None
        The steady-state filter with the ``[payload]`` rest noise levels (the limit of the
        time-varying filter at rest), or None without them.
    identify_observer : KalmanEstimator or None
        The filter with the ``[payload]`` identification noise levels that scores this
        payload, or None (the bank scores ``observer``).
    """

    payload: float
    model: object
    plant: object
    K: np.ndarray
    S: np.ndarray
    observer: Any
    rest_observer: Any = None
    identify_observer: Any = None

    def _law_with(self, observer) -> tuple[np.ndarray, ...]:
        n_y, n_u = observer.C.shape[0], self.K.shape[0]
        E, F, G = observer.linear_form(n_y, n_u)
        return E, F, G, -self.K, np.zeros((n_u, n_y))

    @property
    def law(self) -> tuple[np.ndarray, ...]:
        """``(E, F, G, H, J)`` of the LQG at rest about the target (:mod:`flexctrl.loop.verdict`).

        With the rest filter when the design has one: the law a run ends with.
        """
        return self._law_with(self.rest_observer or self.observer)

    @property
    def laws(self) -> tuple[tuple[np.ndarray, ...], ...]:
        """The law with the moving filter, and with the rest filter when there is one."""
        observers = [self.observer] + ([self.rest_observer] if self.rest_observer else [])
        return tuple(self._law_with(o) for o in observers)


def model_with_payload(model, payload: float):
    """``model`` rebuilt carrying ``payload`` kg (fidelity, mode option and configuration kept).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        A model built by :func:`flexctrl.dynamics.build.build_model`.
    payload : float
        kg.

    Returns
    -------
    Model
    """
    if model.spec.payload.mass == payload:
        return model
    info = model.info
    return build_model(
        model.spec.with_payload(float(payload)),
        model.fidelity,
        modes=info.get("modes", "frozen"),
        reference_q=info.get("reference_q"),
    )


def loop_radius(plant, law) -> float:
    """Spectral radius of ``law`` closed with the sampled ``plant`` (a :class:`LinearPlant`).

    The map of :mod:`flexctrl.loop.verdict`, ``s = (dx, xi, du_prev)``.
    """
    A, B = plant.Ad, plant.Bd
    C, D = (np.asarray(m, dtype=float) for m in (plant.sysd.C, plant.sysd.D))
    E, F, G, H, J = law
    n, m, p = A.shape[0], E.shape[0], B.shape[1]
    xi = np.hstack([F @ C, E, F @ D + G])
    du = H @ xi + J @ np.hstack([C, np.zeros((C.shape[0], m)), D])
    dx = np.hstack([A, np.zeros((n, m + p))]) + B @ du
    return float(np.max(np.abs(np.linalg.eigvals(np.vstack([dx, xi, du])))))


class PayloadGrid:
    """Designs at every payload of ``settings.payload``'s grid, at the target ``q`` (rad).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model (its payload is replaced by each grid payload).
    q : sequence of float
        Target joint angles, rad.
    settings : LQRSettings or MPCSettings
        The recipe (sample time, weights, sensors, estimator) and the ``payload`` table.

    Attributes
    ----------
    payloads : ndarray
        The grid, kg.
    designs : list of PointDesign
    build_time_s : float
        Wall time of the build, s.
    """

    def __init__(self, model, q, settings):
        if settings.payload is None:
            raise SpecError(
                "no [payload] table; allowed: settings with a payload range", key="payload"
            )
        start = time.perf_counter()
        self.settings = settings
        self.q = tuple(float(a) for a in q)
        self.payloads = np.array(settings.payload.grid_points(), dtype=float)
        self.designs = [self._design(model, m) for m in self.payloads]
        self.A, self.B, self.C, self.D, self.M = (
            np.array([getattr(d.observer, name) for d in self.designs])
            for name in ("A", "B", "C", "D", "M")
        )
        self.K = np.array([d.K for d in self.designs])
        self.P = np.array([d.observer.P for d in self.designs])
        self.R = np.array([d.observer.R for d in self.designs])
        rests = [d.rest_observer for d in self.designs]
        self.W_rest = np.array([o.W for o in rests]) if rests[0] is not None else None
        scorers = [d.identify_observer or d.observer for d in self.designs]
        #: Gains of the filters that score the payloads (``M`` when they are the control ones).
        self.M_identify = np.array([o.M for o in scorers])
        covariances = [o.C @ o.P @ o.C.T + o.R for o in scorers]
        self.S_inv = np.array([np.linalg.inv(s) for s in covariances])
        self.logdet = np.array([np.linalg.slogdet(s)[1] for s in covariances])
        self.x_op = np.array([d.observer.op.x for d in self.designs])
        self.u_op = np.array([d.observer.op.u for d in self.designs])
        self.y_op = np.array([d.observer.y_op for d in self.designs])
        self.build_time_s = time.perf_counter() - start

    def _plant(self, model, payload: float):
        """``model`` carrying ``payload`` kg and its :class:`LinearPlant` at the target."""
        s = self.settings
        model_m = model_with_payload(model, payload)
        op = equilibrium(model_m, self.q)
        sensors = build_sensors(model_m, s.sensors, op)
        if sensors.full_state:
            raise SpecError(
                "a payload-aware controller identifies the payload from what an arm measures; "
                "allowed: sensors without 'state' (e.g. joints and strain)",
                key="sensors.outputs",
            )
        lin = Linearizer(model_m, sensors)
        return model_m, linear_plant(model_m, op, sensors, s.sample_time, lin)

    def _design(self, model, payload: float) -> PointDesign:
        s = self.settings
        model_m, plant = self._plant(model, payload)
        op, sensors = plant.op, plant.sensors
        Q, R = weight_matrices(model_m, s.weights, torque_limits(model_m))
        K, S = lqr_gain(plant.Ad, plant.Bd, Q, R)
        observer = make_observer(model_m, op, sensors, plant.sys.A, plant.sysd, s.estimator)
        extra = {}
        for prefix in ("rest", "identify"):
            if getattr(s.payload, f"{prefix}_torque_noise") is not None:
                levels = EstimatorSettings(
                    torque_noise=getattr(s.payload, f"{prefix}_torque_noise"),
                    modal_force_noise=getattr(s.payload, f"{prefix}_modal_force_noise"),
                )
                extra[prefix] = make_observer(model_m, op, sensors, plant.sys.A, plant.sysd, levels)
        return PointDesign(
            float(payload),
            model_m,
            plant,
            K,
            S,
            observer,
            extra.get("rest"),
            extra.get("identify"),
        )

    def index_at_or_below(self, payload: float) -> int:
        """Index of the largest grid payload at or below ``payload`` (kg; the first if none).

        A payload within ``SNAP`` of a grid step below a grid payload counts as that payload:
        a posterior concentrated on one grid payload keeps a spread of order
        ``step * sqrt(p)`` from the probabilities ``p`` left on its neighbours (1e-9 leaves
        1e-5 kg), and without the snap the light side would always run one step light.
        """
        payloads = self.payloads
        i = max(int(np.searchsorted(payloads, payload, side="right")) - 1, 0)
        if i + 1 < len(payloads) and payloads[i + 1] - payload <= SNAP * (
            payloads[i + 1] - payloads[i]
        ):
            i += 1
        return i

    def certificate(self) -> list[dict]:
        """The linear verdict of each design on the plants it may run on.

        Returns
        -------
        list of dict
            One row per grid interval ``[m_i, m_{i+1}]``: ``design_kg``, ``plant_kg``
            (``m_i``, the midpoint, ``m_{i+1}``), ``radius`` (the three radii of the law a run
            ends with, the rest filter's when there is one), ``radius_moving`` (the same with
            the moving filter) and ``worst`` (the largest of them).
        """
        rows = []
        for i, design in enumerate(self.designs[:-1]):
            low, high = self.payloads[i], self.payloads[i + 1]
            middle = self._plant(design.model, 0.5 * (low + high))[1]
            plants = (design.plant, middle, self.designs[i + 1].plant)
            radii = tuple(loop_radius(p, design.law) for p in plants)
            moving = tuple(loop_radius(p, design.laws[0]) for p in plants)
            rows.append(
                {
                    "design_kg": float(low),
                    "plant_kg": (float(low), 0.5 * float(low + high), float(high)),
                    "radius": radii,
                    "radius_moving": moving,
                    "worst": max(radii + moving),
                }
            )
        return rows


def check_certificate(rows: list[dict], source: str = "") -> list[dict]:
    """Warn once, naming the first grid cell whose design is not stable on its plants.

    Parameters
    ----------
    rows : list of dict
        :meth:`PayloadGrid.certificate`.
    source : str
        What the grid belongs to (a controller file), for the message.

    Returns
    -------
    list of dict
        The failing rows.
    """
    failing = [r for r in rows if r["worst"] >= CERTIFICATE_LIMIT]
    if failing:
        r = failing[0]
        per_plant = np.maximum(r["radius"], r.get("radius_moving", r["radius"]))
        worst = r["plant_kg"][int(np.argmax(per_plant))]
        warnings.warn(
            f"{source + ': ' if source else ''}payload grid too coarse for the certificate: the "
            f"design at {r['design_kg']:g} kg has closed-loop radius {r['worst']:.4f} on the "
            f"{worst:g} kg plant ({len(failing)} of {len(rows)} grid cells fail); use a finer "
            "grid there",
            stacklevel=2,
        )
    return failing


__all__ = [
    "PayloadGrid",
    "PointDesign",
    "model_with_payload",
    "loop_radius",
    "check_certificate",
    "CERTIFICATE_LIMIT",
]
