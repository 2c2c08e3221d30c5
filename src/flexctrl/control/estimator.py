"""State estimation for the state-feedback controllers (LQR, MPC, NMPC).

:class:`FullState` passes a full-state measurement through.  :class:`KalmanEstimator`
is the steady-state discrete Kalman filter on the ZOH-discretised linearisation at
the target, in *current-estimate* form (the estimate at ``t_k`` uses the measurement
taken at ``t_k``, so a controller can act on it in the same sample)::

    predict   dx- = A dx + B du_{k-1}
    correct   dx  = dx- + M (dy_k - C dx- - D du_{k-1})      M = P C' (C P C' + R)^-1

``P`` is the a-priori covariance from the filter DARE ``P = A P A' - A P C'(C P C' + R)^-1 C P A' +
W``; ``python-control``'s ``dlqe`` returns the predictor gain ``L = A M`` of the same filter.
``du_{k-1}`` is the torque held during the sample that just ended (it also drives the feed-through
of tip accelerometers).  Process noise ``W`` comes from generalised-force disturbances held over a
sample (torques on the joints, forces on the elastic coordinates), mapped through the exact ZOH
input matrix of ``[0; M(q)^-1]``. The first estimate after :meth:`KalmanEstimator.reset` is the
least-squares fit of the first measurement, ``dx = C^+ (dy - D du)``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.linalg

from flexctrl.control.riccati import solve_dare
from flexctrl.linear import OperatingPoint, Sensors


class FullState:
    """The measurement *is* the state.

    Parameters
    ----------
    Ad, Bd : ndarray, optional
        The discrete linearisation the state is predicted with through a skipped sample
        (:meth:`predict`); without them nothing can be predicted.
    op : OperatingPoint, optional
        Where ``Ad``, ``Bd`` were taken (deviations are about it).
    """

    def __init__(self, Ad=None, Bd=None, op: OperatingPoint | None = None):
        self.A = None if Ad is None else np.asarray(Ad, dtype=float)
        self.B = None if Bd is None else np.asarray(Bd, dtype=float)
        self.op = op
        self.dx: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the last state (nothing to predict from until the next measurement)."""
        self.dx = None

    def estimate(self, y: np.ndarray, u_previous: np.ndarray) -> np.ndarray:
        """The state ``y``."""
        if self.op is not None:
            self.dx = y - self.op.x
        return y

    def predict(self, u_previous: np.ndarray) -> np.ndarray | None:
        """The state one sample after the last, ``A dx + B du`` about ``op``, or None.

        None without a last state or without the linearisation.  The prediction becomes the
        last state, so skipped samples in a row chain their predictions.
        """
        if self.dx is None or self.A is None or self.B is None or self.op is None:
            return None
        du = np.asarray(u_previous, dtype=float) - self.op.u
        self.dx = self.A @ self.dx + self.B @ du
        return self.op.x + self.dx

    def linear_form(self, n_y: int, n_u: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(E, F, G)`` of ``x_k = E x_{k-1} + F dy_k + G du_{k-1}``: the measurement itself."""
        return np.zeros((n_y, n_y)), np.eye(n_y), np.zeros((n_y, n_u))

    @property
    def memory(self) -> np.ndarray:
        """No memory (an empty vector)."""
        return np.zeros(0)

    def restore(self, memory: np.ndarray) -> None:
        """Forget the last state: the chained samples that ran elsewhere kept none."""
        self.dx = None

    def symbolic(self, memory, y, u_previous):
        """``(memory_next, x)``: :meth:`estimate` on CasADi symbols."""
        return memory, y

    def symbolic_start(self, y, u_previous):
        """``(memory, x)``: the first :meth:`estimate` after :meth:`reset` on CasADi symbols."""
        return ca.MX(0, 1), y


def zoh_input_matrix(A: np.ndarray, G: np.ndarray, dt: float) -> np.ndarray:
    """``int_0^dt exp(A s) ds G``: the exact discrete input matrix of a held input.

    Parameters
    ----------
    A : ndarray
        The continuous state matrix, 1/s.
    G : ndarray
        The continuous input matrix.
    dt : float
        The hold, s.

    Returns
    -------
    ndarray
    """
    n, m = G.shape
    aug = np.zeros((n + m, n + m))
    aug[:n, :n], aug[:n, n:] = A * dt, G * dt
    return scipy.linalg.expm(aug)[:n, n:]


def process_noise(
    model,
    op: OperatingPoint,
    A: np.ndarray,
    dt: float,
    torque_noise: float,
    modal_force_noise: float,
) -> np.ndarray:
    """Discrete process-noise covariance of held generalized-force disturbances.

    See the module docstring: torques on the joints and forces on the elastic coordinates,
    held over a sample, through the exact ZOH input matrix of ``[0; M(q)^-1]``.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        Its mass matrix at ``op``.
    op : OperatingPoint
        Where the filter is designed.
    A : ndarray
        The continuous state matrix of the linearization, 1/s.
    dt : float
        The sample time, s.
    torque_noise : float
        Standard deviation of the joint torque disturbances, N m.
    modal_force_noise : float
        Standard deviation of the forces on the elastic coordinates (their units).

    Returns
    -------
    ndarray
        The symmetric covariance ``W`` (2N x 2N).
    """
    N, n = model.n_q, model.n_u
    Minv = np.linalg.inv(model.mass_matrix(op.q))
    G = np.vstack([np.zeros((N, N)), Minv])
    Gd = zoh_input_matrix(A, G, dt)
    sigma = np.r_[np.full(n, torque_noise), np.full(N - n, modal_force_noise)]
    W = Gd @ np.diag(sigma**2) @ Gd.T
    return 0.5 * (W + W.T)


def kalman_gain(
    Ad: np.ndarray, Cd: np.ndarray, W: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Current-estimate Kalman gain ``M`` and a-priori covariance ``P`` (filter DARE).

    The filter DARE is the dual of the control one, ``(A, B, Q, R) -> (A', C', W, R)``,
    solved by the doubling algorithm of :func:`flexctrl.control.riccati.solve_dare`:
    the Schur method's eigenvalue reordering is ill-conditioned for flexible arms (see that
    module).

    Parameters
    ----------
    Ad, Cd : ndarray
        The discrete state and output matrices.
    W, R : ndarray
        Process and measurement noise covariances.

    Returns
    -------
    tuple of ndarray
        ``(M, P)``.

    Raises
    ------
    SolverError
        No stabilising solution (e.g. a mode on the unit circle that no sensor sees).
    """
    P = solve_dare(Ad.T, Cd.T, W, R, what="Kalman filter")
    S = Cd @ P @ Cd.T + R
    M = np.linalg.solve(S, Cd @ P).T
    return M, P


class KalmanEstimator:
    """Steady-state Kalman filter about ``op`` (see module docstring).

    Parameters
    ----------
    Ad, Bd, Cd, Dd : ndarray
        ZOH-discretised linearisation with the sensors' outputs.
    op : OperatingPoint
    sensors : Sensors
        Gives the noise standard deviations (``R``) and the outputs at ``op``.
    W : ndarray
        Process-noise covariance.
    """

    def __init__(self, Ad, Bd, Cd, Dd, op: OperatingPoint, sensors: Sensors, W: np.ndarray):
        self.A, self.B, self.C, self.D = (np.asarray(m, dtype=float) for m in (Ad, Bd, Cd, Dd))
        self.op = op
        self.y_op = sensors.evaluate(op.x, op.u)
        var = np.maximum(sensors.noise_std**2, 1e-18 * np.maximum(1.0, np.abs(self.y_op)) ** 2)
        self.R = np.diag(var)
        self.W = W
        self.M, self.P = kalman_gain(self.A, self.C, W, self.R)
        self._pinv = np.linalg.pinv(self.C)
        self.dx: np.ndarray | None = None

    def reset(self) -> None:
        """Start again from the next measurement."""
        self.dx = None

    def estimate(self, y: np.ndarray, u_previous: np.ndarray) -> np.ndarray:
        """State estimate (absolute) at the time of measurement ``y``."""
        du = np.asarray(u_previous, dtype=float) - self.op.u
        dy = y - self.y_op - self.D @ du
        if self.dx is None:
            self.dx = self._pinv @ dy
        else:
            pred = self.A @ self.dx + self.B @ du
            self.dx = pred + self.M @ (dy - self.C @ pred)
        return self.op.x + self.dx

    def predict(self, u_previous: np.ndarray) -> np.ndarray | None:
        """The estimate at the next sample without a measurement: ``A dx + B du``, or None.

        The prediction step of :meth:`estimate` alone (a skipped sample); None before the
        first measurement.
        """
        if self.dx is None:
            return None
        du = np.asarray(u_previous, dtype=float) - self.op.u
        self.dx = self.A @ self.dx + self.B @ du
        return self.op.x + self.dx

    @property
    def memory(self) -> np.ndarray:
        """The deviation estimate ``dx`` (after a first measurement)."""
        if self.dx is None:
            raise ValueError("the Kalman filter has no estimate yet: give it a first measurement")
        return np.array(self.dx, dtype=float)

    def restore(self, memory: np.ndarray) -> None:
        """Continue from the deviation estimate ``memory``."""
        self.dx = np.array(memory, dtype=float)

    def symbolic(self, memory, y, u_previous):
        """``(dx_next, x)``: one :meth:`estimate` after the first, on CasADi symbols.

        The same operations as :meth:`estimate`.
        """
        A, B, C, D, M = (ca.DM(m) for m in (self.A, self.B, self.C, self.D, self.M))
        du = u_previous - ca.DM(self.op.u)
        dy = y - ca.DM(self.y_op) - ca.mtimes(D, du)
        pred = ca.mtimes(A, memory) + ca.mtimes(B, du)
        dx = pred + ca.mtimes(M, dy - ca.mtimes(C, pred))
        return dx, ca.DM(self.op.x) + dx

    def symbolic_start(self, y, u_previous):
        """``(dx, x)``: the first :meth:`estimate` after :meth:`reset` on CasADi symbols.

        The least-squares fit ``dx = C^+ (dy - D du)``, the same operations as
        :meth:`estimate` with no estimate yet.
        """
        du = u_previous - ca.DM(self.op.u)
        dy = y - ca.DM(self.y_op) - ca.mtimes(ca.DM(self.D), du)
        dx = ca.mtimes(ca.DM(self._pinv), dy)
        return dx, ca.DM(self.op.x) + dx

    def linear_form(self, n_y: int, n_u: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(E, F, G)`` of the estimate in deviations: ``dx_k = E dx_{k-1} + F dy_k + G du_{k-1}``.

        From the current-estimate form: ``dx_k = T (A dx_{k-1} + B du_{k-1}) +
        M (dy_k - D du_{k-1})`` with ``T = I - M C``.
        """
        T = np.eye(self.A.shape[0]) - self.M @ self.C
        return T @ self.A, self.M, T @ self.B - self.M @ self.D

    @property
    def poles(self) -> np.ndarray:
        """Eigenvalues of the estimation-error dynamics ``(I - M C) A``."""
        return np.linalg.eigvals((np.eye(self.A.shape[0]) - self.M @ self.C) @ self.A)


def make_observer(
    model, op: OperatingPoint, sensors: Sensors, Ac: np.ndarray, sysd, estimator_settings
):
    """:class:`FullState` for a full-state sensor, else the :class:`KalmanEstimator` of ``sysd``.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model.
    op : OperatingPoint
        The target.
    sensors : Sensors
        The controller's sensors.
    Ac : ndarray
        The continuous state matrix of the linearization (for the process noise), 1/s.
    sysd : control.StateSpace
        Its ZOH discretization with the sensors as outputs.
    estimator_settings : EstimatorSettings
        The process noise levels.

    Returns
    -------
    FullState or KalmanEstimator
        Both predict through a skipped sample with ``sysd``.
    """
    if sensors.full_state:
        return FullState(sysd.A, sysd.B, op)
    W = process_noise(
        model,
        op,
        np.asarray(Ac, dtype=float),
        float(sysd.dt),
        estimator_settings.torque_noise,
        estimator_settings.modal_force_noise,
    )
    return KalmanEstimator(sysd.A, sysd.B, sysd.C, sysd.D, op, sensors, W)


__all__ = [
    "FullState",
    "KalmanEstimator",
    "kalman_gain",
    "process_noise",
    "zoh_input_matrix",
    "make_observer",
]
