"""On-line payload identification: a bank of the design's Kalman filters, one per grid payload.

Multiple-model adaptive estimation (MMAE).  Every sample each filter ``i`` of the grid
(:class:`~flexctrl.control.payload.grid.PayloadGrid`) predicts and corrects on the same
measurement, in current-estimate form::

    pred_i = A_i dx_i + B_i du_i             du_i = u_prev - u_op,i - c_rigid(q, qd; m_i)
    nu_i   = dy_i - C_i pred_i - D_i du_i    dy_i = y - y_op,i
    dx_i   = pred_i + M_i nu_i

and the posterior over the grid is updated by the tempered innovation likelihood::

    log p_i <- log max(p_i, floor) + temper * (-1/2) (nu_i' S_i^-1 nu_i + log det S_i)

``c_rigid`` is the rigid model's velocity-product torque, affine in the payload
(``c0 + m c1`` from the rigid model at two payloads), with the joint rates from encoder
differences over two samples: the linearisation at rest drops it, and during a move it
reaches several N m on the outer joints, which the filters would otherwise blame on the
payload.  It is applied only while a joint moves (the excitation gate below): at rest the
encoder differences are noise, and a velocity product squares it into a torque bias that
never averages out (with 0.005 deg encoder noise, 4 kg at pose (30, 0, 90) deg: up to
0.03 N m at a 2 ms sample, 0.002 N m at 8.5 ms; it grows as 1/T^2), which the slow rest
filter turns into a standing joint offset (0.007 deg at 2 ms).  The probabilities change
only while a joint moves: at rest the innovations carry model error and no payload
information.  The estimate is the posterior mean with the posterior standard deviation;
before any motion it is the prior (the range's middle unless the settings say otherwise).

Two banks, two jobs (:class:`~flexctrl.spec.payload_settings.PayloadSettings`): with
``identify_*`` noise levels a second set of filters, with their own process noise, gives the
innovations that score the payloads, and the control filters (the ``[estimator]`` levels)
give the state estimates.  With ``rest_*`` levels the control filters slow down from
``rest_delay`` after the reference stops: each a-priori covariance starts from its moving
steady state ``P_i`` and follows the Riccati recursion with the rest process noise::

    P+ = (I - M C) P,   P <- A P+ A' + W_rest,   M = P C' (C P C' + R)^-1

so the gains fall as samples accumulate and the estimate averages the sensor noise over the
whole time at rest (the recursion tends to the steady-state filter of the rest levels).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from flexctrl.dynamics.build import build_model
from flexctrl.errors import keywords_checked


@keywords_checked
@dataclass(frozen=True)
class PayloadEstimate:
    """What a payload-aware controller believes now.

    Attributes
    ----------
    mean : float
        Posterior mean payload, kg.
    std : float
        Posterior standard deviation, kg.
    design : float
        The grid payload the controller runs its design at, kg.
    excited : bool
        Whether the last update learned (a joint was moving).
    """

    mean: float
    std: float
    design: float
    excited: bool = False


class RigidCoriolis:
    """The rigid model's velocity-product torques ``c(q, qd; m) = c0 + m c1`` (N m).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model (its arm is rebuilt rigid at 0 and 1 kg).
    sample_time : float
        s, for the encoder-difference rates.
    """

    def __init__(self, model, sample_time: float):
        arm = model.spec
        self._c = [build_model(arm.with_payload(m), "rigid").functions["c"] for m in (0.0, 1.0)]
        self.n_u = model.n_u
        self.dt = float(sample_time)
        self._q: deque = deque(maxlen=3)

    def reset(self) -> None:
        """Forget the encoder history."""
        self._q.clear()

    def terms(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(c0, c1)`` at the newest encoder reading ``q`` (rad); zero before two readings."""
        self._q.append(np.array(q, dtype=float))
        if len(self._q) < 2:
            return np.zeros(self.n_u), np.zeros(self.n_u)
        qd = (self._q[-1] - self._q[0]) / ((len(self._q) - 1) * self.dt)
        c0 = np.asarray(self._c[0](self._q[-1], qd), dtype=float).ravel()
        c1 = np.asarray(self._c[1](self._q[-1], qd), dtype=float).ravel() - c0
        return c0, c1


class PayloadBank:
    """The MMAE over a :class:`~flexctrl.control.payload.grid.PayloadGrid` (module docstring).

    Parameters
    ----------
    grid : PayloadGrid
        Filters and innovation covariances per payload.
    settings : PayloadSettings
        Prior, temper, floor, gate, Coriolis compensation.
    coriolis : RigidCoriolis or None
        The velocity-product torques (None: not compensated).
    joints : sequence of int
        Indices of the joint encoders in the measurement vector (for the gate and the rates).
    """

    def __init__(self, grid, settings, coriolis: RigidCoriolis | None, joints):
        self.grid = grid
        self.settings = settings
        self.coriolis = coriolis
        self.joints = np.asarray(joints, dtype=int)
        self._pinv = np.array([np.linalg.pinv(c) for c in grid.C])
        logp = -0.5 * ((grid.payloads - settings.mean0) / settings.std0) ** 2
        prior = np.exp(logp - logp.max())
        self.prior = prior / prior.sum()
        self.p = self.prior.copy()
        self.dx: np.ndarray | None = None
        #: The identification filters' deviations (None: they are the control filters).
        self.dx_identify: np.ndarray | None = None
        self.excited = False
        self._history: deque = deque(maxlen=settings.excitation_window + 1)
        #: The filters' gains now (the moving steady state, or the rest recursion's).
        self.M = grid.M.copy()
        self._P: np.ndarray | None = None
        self.resting = False

    def reset(self) -> None:
        """Back to the prior, the filters to start from the next measurement."""
        self.p = self.prior.copy()
        self.dx = None
        self.dx_identify = None
        self.excited = False
        self._history.clear()
        self.M = self.grid.M.copy()
        self._P = None
        self.resting = False
        if self.coriolis is not None:
            self.coriolis.reset()

    @property
    def mean(self) -> float:
        """Posterior mean payload, kg."""
        return float(self.p @ self.grid.payloads)

    @property
    def std(self) -> float:
        """Posterior standard deviation, kg."""
        spread = self.p @ (self.grid.payloads - self.mean) ** 2
        return float(np.sqrt(max(spread, 0.0)))

    def light_side(self) -> float:
        """``max(lightest, mean - err_light_sigmas * std)``, kg."""
        low = self.settings.range[0]
        return max(low, self.mean - self.settings.err_light_sigmas * self.std)

    def rest(self, resting: bool) -> None:
        """Tell the bank whether the reference rests (no effect without rest noise levels).

        On the first resting sample each filter's a-priori covariance starts from its moving
        steady state; while resting it follows the Riccati recursion with the rest levels
        (:meth:`_advance_covariance`); when the reference moves again the moving gains return.
        """
        if self.grid.W_rest is None or resting == self.resting:
            return
        self.resting = resting
        if resting:
            self._P = self.grid.P.copy()
        else:
            self.M = self.grid.M.copy()
            self._P = None

    def _advance_covariance(self, corrected: bool) -> None:
        """One step of the rest filters' Riccati recursion and their next gains.

        ``P+ = (I - M C) P`` after a correction, ``P <- A P+ A' + W_rest``,
        ``M = P C' (C P C' + R)^-1``.
        """
        if not self.resting or self._P is None:
            return
        g, P = self.grid, self._P
        if corrected:
            P = P - self.M @ (g.C @ P)
        P = g.A @ P @ np.swapaxes(g.A, 1, 2) + g.W_rest
        P = 0.5 * (P + np.swapaxes(P, 1, 2))
        PCt = P @ np.swapaxes(g.C, 1, 2)
        S = g.C @ PCt + g.R
        self.M = np.swapaxes(np.linalg.solve(S, np.swapaxes(PCt, 1, 2)), 1, 2)
        self._P = P

    def _moving(self, q: np.ndarray) -> bool:
        history = self._history
        history.append(q)
        if len(history) < (history.maxlen or 0):
            return False
        rate = np.abs(history[-1] - history[0]) / (
            (len(history) - 1) * self.grid.settings.sample_time
        )
        return bool(np.max(rate) > self.settings.excitation_rate)

    def _inputs(self, q: np.ndarray, u_previous: np.ndarray, moving: bool) -> np.ndarray:
        """Each filter's input deviation; the velocity-product torques only while ``moving``."""
        du = np.asarray(u_previous, dtype=float)[None, :] - self.grid.u_op
        if self.coriolis is not None:
            c0, c1 = self.coriolis.terms(q)  # every sample: it keeps the encoder history
            if not moving:
                return du
            du = du - c0[None, :] - self.grid.payloads[:, None] * c1[None, :]
        return du

    def update(self, y: np.ndarray, u_previous: np.ndarray) -> None:
        """One sample: filter every model on ``y`` and, while moving, reweigh the models.

        Parameters
        ----------
        y : ndarray
            The measurement, in the sensors' units.
        u_previous : ndarray
            The torque held during the sample that just ended, N m.
        """
        g = self.grid
        q = np.asarray(y, dtype=float)[self.joints]
        moving = self._moving(q)
        du = self._inputs(q, u_previous, moving)
        dy = np.asarray(y, dtype=float)[None, :] - g.y_op
        if self.dx is None:
            self.dx = np.einsum("nij,nj->ni", self._pinv, dy - np.einsum("nij,nj->ni", g.D, du))
            if self.settings.identifies_apart:
                self.dx_identify = self.dx.copy()
            return
        self.dx, nu = self._correct(self.dx, self.M, du, dy)
        if self.dx_identify is not None:
            self.dx_identify, nu = self._correct(self.dx_identify, g.M_identify, du, dy)
        self._advance_covariance(corrected=True)
        self.excited = moving
        if moving:
            loglik = -0.5 * (np.einsum("ni,nij,nj->n", nu, g.S_inv, nu) + g.logdet)
            logp = np.log(np.maximum(self.p, self.settings.probability_floor))
            logp = logp + self.settings.temper * loglik
            p = np.exp(logp - logp.max())
            self.p = p / p.sum()

    def _correct(self, dx, M, du, dy) -> tuple[np.ndarray, np.ndarray]:
        """Every filter's predict and correct from ``dx`` with gains ``M``: ``(dx, nu)``."""
        g = self.grid
        pred = np.einsum("nij,nj->ni", g.A, dx) + np.einsum("nij,nj->ni", g.B, du)
        nu = dy - np.einsum("nij,nj->ni", g.C, pred) - np.einsum("nij,nj->ni", g.D, du)
        return pred + np.einsum("nij,nj->ni", M, nu), nu

    def predict(self, u_previous: np.ndarray) -> None:
        """One sample without a measurement: every filter predicts; the posterior is kept."""
        if self.dx is None:
            return
        du = np.asarray(u_previous, dtype=float)[None, :] - self.grid.u_op
        g = self.grid
        self.dx = np.einsum("nij,nj->ni", g.A, self.dx) + np.einsum("nij,nj->ni", g.B, du)
        if self.dx_identify is not None:
            self.dx_identify = np.einsum("nij,nj->ni", g.A, self.dx_identify) + np.einsum(
                "nij,nj->ni", g.B, du
            )
        self._advance_covariance(corrected=False)
        self.excited = False

    def state(self, i: int) -> np.ndarray:
        """Filter ``i``'s absolute state estimate (its deviation plus the design's ``x_op``)."""
        if self.dx is None:
            raise RuntimeError("the bank has no state before its first measurement")
        return self.grid.x_op[i] + self.dx[i]


__all__ = ["PayloadBank", "PayloadEstimate", "RigidCoriolis"]
