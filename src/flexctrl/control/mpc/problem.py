"""The linear MPC's problem data: scaled prediction model, weights, bounds, soft and arrival rows.

Built once from the design model's linearization; :mod:`flexctrl.control.mpc.controller`
describes the problem and the scaling.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from flexctrl.control.lqr import LinearPlant, design_weights, weight_matrices
from flexctrl.control.riccati import lqr_gain
from flexctrl.errors import SpecError
from flexctrl.linear import OperatingPoint


@dataclass(frozen=True, eq=False)
class ScaledProblem:
    """The MPC data in scaled deviation variables.

    Attributes
    ----------
    A, B, Q, R, P : ndarray
        Scaled dynamics and weights (``P``: terminal).
    K : ndarray
        Scaled LQR gain (``v = -K z``).
    Sx, Su : ndarray
        Scales: ``dx = Sx * z``, ``du = Su * v``.
    v_lo, v_hi : ndarray
        Scaled input bounds.
    C, c_lo, c_hi : ndarray
        Scaled soft rows and their bounds (``C z in [c_lo, c_hi]``); zero rows if none.
    h : float
        Soft-row scale (m): physical violation = ``h * s``.
    l1, l2 : float
        Scaled slack penalties.
    horizon : int
        Prediction steps N.
    n_arrival : int
        The last ``n_arrival`` soft rows are the arrival rows (:func:`arrival_rows`).
    row_scale : ndarray or None
        Per soft row, the physical violation of one unit of its slack (m, rad, rad/s);
        None: ``h`` for every row.
    hard : ndarray of bool or None
        Per soft row, whether its slack is held at zero (a hard bound); None: none is.
    rate_joints : ndarray of int
        The joints (0-based) with torque-rate bounds.
    rate_lo, rate_hi : ndarray
        Their bounds on ``v_k - v_(k-1)`` (scaled: ``Ts * bound / S_u``).
    """

    A: np.ndarray
    B: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    P: np.ndarray
    K: np.ndarray
    Sx: np.ndarray
    Su: np.ndarray
    v_lo: np.ndarray
    v_hi: np.ndarray
    C: np.ndarray
    c_lo: np.ndarray
    c_hi: np.ndarray
    h: float
    l1: float
    l2: float
    horizon: int
    n_arrival: int = 0
    row_scale: np.ndarray | None = None
    hard: np.ndarray | None = None
    rate_joints: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    rate_lo: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rate_hi: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def slack_violation(self, slack: np.ndarray) -> float:
        """The largest physical violation (the row's unit) of the slacks ``slack`` (stage-major)."""
        if not slack.size:
            return 0.0
        scale = self.h if self.row_scale is None else self.row_scale
        return float(np.max(slack.reshape(-1, self.ns) * scale))

    @property
    def n(self) -> int:
        """States."""
        return self.A.shape[0]

    @property
    def m(self) -> int:
        """Inputs."""
        return self.B.shape[1]

    @property
    def ns(self) -> int:
        """Soft rows (with the arrival rows)."""
        return self.C.shape[0]


def state_scales(
    plant: LinearPlant,
    K: np.ndarray,
    Q: np.ndarray,
    n_u: int,
    kind: str,
    joint_error: float,
    duration: float = 5.0,
) -> np.ndarray:
    """State scales ``S_x`` (:mod:`flexctrl.control.mpc.controller`, "Scaling").

    Parameters
    ----------
    plant : LinearPlant
        The discrete linearization.
    K : ndarray
        The LQR gain whose closed-loop responses set the ``"auto"`` scales.
    Q : ndarray
        The state weight (Bryson's rule: ``1 / x_max^2`` on its diagonal).
    n_u : int
        Joints.
    kind : {"auto", "bryson", "none"}
        The scaling.
    joint_error : float
        The acceptable joint error each joint is displaced by (``"auto"``), rad.
    duration : float
        How long the responses are followed, s.

    Returns
    -------
    ndarray
        One scale per state.
    """
    nx = plant.Ad.shape[0]
    if kind == "none":
        return np.ones(nx)
    bryson = 1.0 / np.sqrt(np.diag(Q))
    if kind == "bryson":
        return bryson
    Acl = plant.Ad - plant.Bd @ K
    steps = max(1, int(round(duration / plant.dt)))
    peak = np.zeros(nx)
    for j in range(n_u):
        x = np.zeros(nx)
        x[j] = joint_error
        for _ in range(steps):
            peak = np.maximum(peak, np.abs(x))
            x = Acl @ x
    N = nx // 2
    groups = [np.arange(n_u), np.arange(n_u, N), N + np.arange(n_u), np.arange(N + n_u, nx)]
    for g in groups:
        if g.size:
            peak[g] = np.maximum(
                peak[g], 1e-2 * np.max(peak[g]) if np.max(peak[g]) > 0 else bryson[g]
            )
    return peak


def soft_rows(
    model, op: OperatingPoint, settings
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The soft rows on the state, their values at ``op``, their limits and their scale.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        Its link deflections or tip position.
    op : OperatingPoint
        The target.
    settings : MPCSettings or NMPCSettings
        Which soft constraint (``soft``) and its limit.

    Returns
    -------
    tuple
        ``(C_s, values, limits, scale)``: rows (per state, m), values at ``op`` (m; zero for
        the tip error), limits (m) and the row scale (m; the limit, or the modal weight when
        the limit is 0).
    """
    N = model.n_q
    q = ca.SX.sym("q", N)
    if settings.soft == "deflection":
        expr = model.functions["deflection"](q)[0]
        limit = settings.deflection_limit
    elif settings.soft == "tip":
        expr = model.functions["tip"](q, ca.SX.zeros(N))[0]
        limit = settings.tip_limit
    else:
        return np.zeros((0, 2 * N)), np.zeros(0), np.zeros(0), 1.0
    fun = ca.Function("soft", [q], [expr, ca.jacobian(expr, q)])
    value, jac = (np.array(v, dtype=float) for v in fun(op.q))
    value = value.ravel()
    rows = np.hstack([jac, np.zeros_like(jac)])
    keep = (
        np.any(rows != 0, axis=1) if settings.soft == "deflection" else np.ones(rows.shape[0], bool)
    )
    if settings.soft == "tip":
        value = np.zeros_like(value)  # the error from the target tip position
    scale = limit if limit > 0 else settings.weights.modal
    return rows[keep], value[keep], np.full(int(keep.sum()), limit), scale


def arrival_rows(model, op: OperatingPoint) -> np.ndarray:
    """Arrival rows on the state (m): the tip position error, then each joint's as tip motion.

    Row ``j`` of the joint part is ``|d tip / d q_j| e_j``: the tip displacement that joint
    ``j``'s error alone causes at ``op`` (a tip inside the band with the joints off
    target would be another, redundant configuration of the arm).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        Its tip position.
    op : OperatingPoint
        The target.

    Returns
    -------
    ndarray
        The rows (tip components, then one per joint) by the state.
    """
    N = model.n_q
    q = ca.SX.sym("q", N)
    tip = model.functions["tip"](q, ca.SX.zeros(N))[0]
    jac = np.array(ca.Function("tip_jacobian", [q], [ca.jacobian(tip, q)])(op.q), dtype=float)
    joints = np.zeros((model.n_u, 2 * N))
    joints[np.arange(model.n_u), np.arange(model.n_u)] = np.linalg.norm(jac[:, : model.n_u], axis=0)
    return np.vstack([np.hstack([jac, np.zeros_like(jac)]), joints])


def _joint(model, bound, what: str) -> int:
    if bound.index >= model.n_u:
        raise SpecError(
            f"value {bound.signal!r} names {what} {bound.index + 1} of a {model.n_u}-joint arm; "
            f"allowed: 1..{model.n_u}",
            key=f"constraints.{bound.signal}",
        )
    return bound.index


def bound_rows(model, op: OperatingPoint, bounds, weights, h: float):
    """The state bounds of ``bounds`` as rows on the state, linearised at ``op``.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The model predicted with.
    op : OperatingPoint
        The target (where the deflections and the tip are linearised).
    bounds : sequence of Bound
        The MPC's bounds (:mod:`flexctrl.spec.mpc_constraints`); torque rates are skipped.
    weights : Weights
        Their magnitudes scale the joint rows (rad, rad/s).
    h : float
        The scale of the deflection and tip rows, m (the soft rows').

    Returns
    -------
    tuple of ndarray
        ``(rows, value, lower, upper, scale, hard)``: rows by the state (physical units per
        state unit), the signals' values at ``op``, the bounds, each row's scale and
        whether it is hard.

    Raises
    ------
    SpecError
        For a joint or link the model does not have, a link without modes, or a hard
        bound the target itself breaks.
    """
    N = model.n_q
    q = ca.SX.sym("q", N)
    maps = ca.Function(
        "bounded",
        [q],
        [
            model.functions["deflection"](q)[0],
            ca.jacobian(model.functions["deflection"](q)[0], q),
            model.functions["tip"](q, ca.SX.zeros(N))[0],
            ca.jacobian(model.functions["tip"](q, ca.SX.zeros(N))[0], q),
        ],
    )
    w, dw, tip, dtip = (np.array(v, dtype=float) for v in maps(op.q))
    out: list[tuple] = []
    for b in bounds:
        row = np.zeros(2 * N)
        if b.kind == "q":
            row[_joint(model, b, "joint")] = 1.0
            value, scale = op.x[b.index], weights.joint
        elif b.kind == "dq":
            row[N + _joint(model, b, "joint")] = 1.0
            value, scale = op.x[N + b.index], weights.joint_rate
        elif b.kind == "w":
            if b.index >= dw.shape[0] or not np.any(dw[b.index] != 0):
                raise SpecError(
                    f"value {b.signal!r} names a link without modes (or none) of this model; "
                    "allowed: links with elastic coordinates",
                    key=f"constraints.{b.signal}",
                )
            row[:N] = dw[b.index]
            value, scale = w[b.index, 0], h
        elif b.kind == "tip":
            row[:N] = dtip[b.index]
            value, scale = tip[b.index, 0], h
        else:
            continue
        if not b.soft and not b.lower <= value <= b.upper:
            raise SpecError(
                f"the target has {b.signal} = {value:.6g}, outside the hard bound "
                f"[{b.lower:g}, {b.upper:g}] (SI units): the MPC could never settle there; "
                "allowed: a hard bound the target satisfies, or a soft one",
                key=f"constraints.{b.signal}",
            )
        out.append((row, value, b.lower, b.upper, scale, not b.soft))
    if not out:
        empty = np.zeros(0)
        return np.zeros((0, 2 * N)), empty, empty, empty, empty, np.zeros(0, bool)
    rows, value, lo, hi, scale, hard = zip(*out)
    return (
        np.array(rows),
        *(np.array(v, dtype=float) for v in (value, lo, hi, scale)),
        np.array(hard, bool),
    )


def _rate_bounds(model, bounds, sample_time: float, scale_u: np.ndarray):
    """``(joints, lo, hi)`` of the torque-rate bounds, scaled to ``v_k - v_(k-1)``."""
    rates = [b for b in bounds if b.kind == "du"]
    joints = np.array([_joint(model, b, "joint") for b in rates], dtype=int)
    lo = np.array([b.lower * sample_time for b in rates]) / scale_u[joints]
    hi = np.array([b.upper * sample_time for b in rates]) / scale_u[joints]
    return joints, lo, hi


def scaled_problem(model, plant: LinearPlant, settings, limits: np.ndarray) -> ScaledProblem:
    """Weights, terminal cost, scaling and constraints of the MPC at ``plant.op``.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The model predicted with.
    plant : LinearPlant
        Its discrete linearization at the target.
    settings : MPCSettings or NMPCSettings
        Weights (Bryson magnitudes, or raw ``Q``, ``R`` where given: :func:`design_weights`),
        terminal cost, scaling, soft constraint, slack penalties, horizon, arrival.
    limits : ndarray
        Torque limits per joint, N m.

    Returns
    -------
    ScaledProblem
    """
    Q, R = design_weights(model, settings, limits)
    K, S = lqr_gain(plant.Ad, plant.Bd, Q, R)
    scale_u = np.where(np.isfinite(limits), limits, 1.0) * settings.weights.torque
    bryson, _ = weight_matrices(model, settings.weights, limits)  # the scales' magnitudes
    Sx = state_scales(
        plant, K, bryson, model.n_u, getattr(settings, "scaling", "auto"), settings.weights.joint
    )
    Sxi = 1.0 / Sx
    A = Sxi[:, None] * plant.Ad * Sx[None, :]
    B = Sxi[:, None] * plant.Bd * scale_u[None, :]
    Qs = Sx[:, None] * Q * Sx[None, :]
    Rs = scale_u[:, None] * R * scale_u[None, :]
    Pt = S if getattr(settings, "terminal", "dare") == "dare" else Q
    Ps = Sx[:, None] * Pt * Sx[None, :]
    Ks = (1.0 / scale_u)[:, None] * K * Sx[None, :]
    u_op = plant.op.u
    v_lo = (-limits - u_op) / scale_u
    v_hi = (limits - u_op) / scale_u
    rows, value, limit, h = soft_rows(model, plant.op, settings)
    bounds = getattr(settings, "constraints", ())
    b_rows, b_value, b_lo, b_hi, b_scale, b_hard = bound_rows(
        model, plant.op, bounds, settings.weights, h
    )
    arrival = getattr(settings, "arrival", None)
    extra, band = np.zeros((0, rows.shape[1])), 0.0
    if arrival is not None and arrival.enabled:
        # the arrival rows after the soft rows and bounds, the error from the target
        extra, band = arrival_rows(model, plant.op), arrival.band
    n_arrival = extra.shape[0]
    scale = np.r_[np.full(rows.shape[0], h), b_scale, np.full(n_arrival, h)]
    lower = np.r_[-limit - value, b_lo - b_value, np.full(n_arrival, -band)]
    upper = np.r_[limit - value, b_hi - b_value, np.full(n_arrival, band)]
    C = np.vstack([rows, b_rows, extra]) * Sx[None, :] / scale[:, None]
    hard = np.r_[np.zeros(rows.shape[0], bool), b_hard, np.zeros(n_arrival, bool)]
    rate_joints, rate_lo, rate_hi = _rate_bounds(model, bounds, plant.dt, scale_u)
    return ScaledProblem(
        A=A,
        B=B,
        Q=Qs,
        R=Rs,
        P=0.5 * (Ps + Ps.T),
        K=Ks,
        Sx=Sx,
        Su=scale_u,
        v_lo=v_lo,
        v_hi=v_hi,
        C=C,
        c_lo=lower / scale,
        c_hi=upper / scale,
        h=h,
        l1=settings.slack_l1 * h,
        l2=settings.slack_l2 * h * h,
        horizon=settings.horizon,
        n_arrival=n_arrival,
        row_scale=scale if b_rows.shape[0] else None,
        hard=hard if np.any(hard) else None,
        rate_joints=rate_joints,
        rate_lo=rate_lo,
        rate_hi=rate_hi,
    )


__all__ = [
    "ScaledProblem",
    "arrival_rows",
    "bound_rows",
    "scaled_problem",
    "soft_rows",
    "state_scales",
]
