"""Linear MPC on the discretised linearisation at the design point: one QP per sample, built once.

Problem (deviations from the reference over the horizon, scaled, see below)::

    min  1/2 sum_{k<N} (z_k' Q z_k + v_k' R v_k) + 1/2 z_N' P z_N + sum_k (l1 s_k + 1/2 l2 s_k^2)
    s.t. z_0 = z(t),   z_{k+1} = A z_k + B v_k,
         u_min - u_ref,k <= v_k <= u_max - u_ref,k                      (hard: torque limits)
         lo - c_op - C r_k+1 - s_k <= C z_{k+1} <= hi - c_op - C r_k+1 + s_k,  s_k >= 0
                                                                 (soft: deflection or tip error)

with ``z_k = x_k - x_ref(t + k Ts)``, ``v_k = u_k - u_ref(t + k Ts)`` and ``r_k = x_ref(t + k Ts) - x_op``
(:mod:`flexctrl.control.reference`: the joint path, its quasi-static deflection and the
feed-forward torque; with no reference ``x_ref = x_op``, ``u_ref = u_op``).  The
prediction ``x_k+1 - x_ref,k+1 = A (x_k - x_ref,k) + B (u_k - u_ref,k)`` uses the
Jacobians of the design point along the reference: exact for a reference that is a
trajectory of the linear model, and without steady-state offset at a target
equilibrium away from the design point (the target's holding torque is ``u_ref``).
Only the bounds depend on the reference, so between samples only vectors change.

``P`` is the DARE solution (``terminal = "dare"``), so without active constraints the
first move is the LQR move ``-K z(t)``.  The slack makes the QP feasible for any
initial state; ``l1`` is an exact penalty (constraints hold whenever they can, for
``l1`` above the multipliers), ``l2`` keeps the Hessian positive definite.

Formulations
    ``sparse``: variables ``[z_0, v_0, s_0, z_1, v_1, s_1, ..., z_N]`` (stage-wise, the
    order HPIPM wants), dynamics as equality rows; between samples only the bounds of
    ``z_0`` change (OSQP ``update(l=, u=)``), so the sparsity and the KKT factorisation
    never change.  ``condensed``: states eliminated, variables ``[v, s]``, dense Hessian;
    ``z(t)`` enters the linear cost and the bounds of the soft rows.

Scaling
    ``z = S_x^-1 dx``, ``v = S_u^-1 du`` with ``S_u`` the torque magnitudes of the
    weights.  ``scaling = "auto"``: ``S_x`` is the largest excursion of each state in
    LQR closed-loop responses from each joint displaced by the acceptable joint error
    (floored at 1 % of the largest of its kind), so states are O(1) in normal
    operation; ``"bryson"``: ``S_x`` = the acceptable magnitudes (``Q = I``); ``"none"``.
    Soft rows are divided by their limit (or the modal weight when the limit is 0).

Backends
    ``osqp`` (the ``osqp`` package, warm-started with the shifted previous primal and
    dual solution or the previous one), or ``hpipm``/``daqp``/``qpoases`` through
    ``casadi.conic`` (HPIPM needs the sparse stage-wise form; its soft rows act on
    ``A z_k + B v_k``, which is the same constraint on ``z_{k+1}``).

Fallback
    When the QP is not solved (OSQP ``max_iter``/``time_limit`` reached, infeasible,
    or a conic failure), ``fallback = "shift"`` applies the previous plan shifted by
    the number of samples since it was computed and, once that runs out, the LQR move;
    ``"lqr"`` the LQR move; ``"hold"`` the previous torque.  Every fallback is recorded in
    :attr:`Controller.stats`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from flexctrl.control.base import Controller
from flexctrl.control.estimator import make_observer
from flexctrl.control.lqr import LinearPlant, build_sensors, linear_plant, lqr_gain, weight_matrices
from flexctrl.spec.controller_settings import MPCSettings
from flexctrl.linear import OperatingPoint, torque_limits

OSQP_OK = {1: "solved", 2: "solved_inaccurate"}


# --------------------------------------------------------------------------------------
# problem data
# --------------------------------------------------------------------------------------
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

    @property
    def n(self) -> int:
        return self.A.shape[0]

    @property
    def m(self) -> int:
        return self.B.shape[1]

    @property
    def ns(self) -> int:
        return self.C.shape[0]


def state_scales(plant: LinearPlant, K: np.ndarray, Q: np.ndarray, n_u: int, kind: str, joint_error: float,
                 duration: float = 5.0) -> np.ndarray:
    """State scales ``S_x`` (see the module docstring)."""
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
            peak[g] = np.maximum(peak[g], 1e-2 * np.max(peak[g]) if np.max(peak[g]) > 0 else bryson[g])
    return peak


def soft_rows(model, op: OperatingPoint, settings) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Physical soft rows ``C_s`` (on the state), their values at ``op`` and the limits (m), and the row scale."""
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
    keep = np.any(rows != 0, axis=1) if settings.soft == "deflection" else np.ones(rows.shape[0], bool)
    if settings.soft == "tip":
        value = np.zeros_like(value)  # the error from the target tip position
    scale = limit if limit > 0 else settings.weights.modal
    return rows[keep], value[keep], np.full(int(keep.sum()), limit), scale


def scaled_problem(model, plant: LinearPlant, settings, limits: np.ndarray) -> ScaledProblem:
    """Weights, terminal cost, scaling and constraints of the MPC at ``plant.op``."""
    Q, R = weight_matrices(model, settings.weights, limits)
    K, S = lqr_gain(plant.Ad, plant.Bd, Q, R)
    scale_u = np.where(np.isfinite(limits), limits, 1.0) * settings.weights.torque
    Sx = state_scales(plant, K, Q, model.n_u, getattr(settings, "scaling", "auto"), settings.weights.joint)
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
    C = rows * Sx[None, :] / h
    return ScaledProblem(A, B, Qs, Rs, 0.5 * (Ps + Ps.T), Ks, Sx, scale_u, v_lo, v_hi, C, (-limit - value) / h,
                         (limit - value) / h, h, settings.slack_l1 * h, settings.slack_l2 * h * h, settings.horizon)


# --------------------------------------------------------------------------------------
# QP formulations
# --------------------------------------------------------------------------------------
@dataclass(eq=False)
class QP:
    """``min 1/2 w'Hw + g'w  s.t.  lba <= A w <= uba,  lbx <= w <= ubx`` with ``z(t)`` entering affinely.

    ``g = g0 + Gz @ z``; ``lba/uba = lba0/uba0 + Lz @ z`` (rows ``Lz`` nonzero only for the
    condensed soft rows); ``lbx[ix0] = ubx[ix0] = z`` (sparse: the initial state).
    ``first_move`` indexes ``v_0`` in ``w``; ``shift_w``/``shift_a`` map a solution to its
    shifted warm start (index arrays).  ``slack`` indexes all ``s``.
    """

    H: sp.csc_matrix
    g0: np.ndarray
    A: sp.csc_matrix
    lba0: np.ndarray
    uba0: np.ndarray
    lbx: np.ndarray
    ubx: np.ndarray
    Gz: np.ndarray | None
    Lz: np.ndarray | None
    ix0: np.ndarray
    first_move: np.ndarray
    moves: np.ndarray  # (N, m) indices of every v_k
    slack: np.ndarray
    shift_w: np.ndarray
    shift_a: np.ndarray
    stages: dict  # structure for HPIPM (N, nx, nu, ng) or {}
    n_state: int
    soft_rows: np.ndarray  # (N, 2 ns): the general rows of the soft constraints of each stage

    def vectors(self, z: np.ndarray, dv: np.ndarray | None = None, dc: np.ndarray | None = None):
        """``(g, lba, uba, lbx, ubx)`` for the current scaled state ``z``.

        ``dv`` (N, m) and ``dc`` (N, ns) shift the input bounds and the soft-row bounds of
        each stage down (the scaled reference input and soft-row value, see the module docstring).
        """
        g = self.g0 if self.Gz is None else self.g0 + self.Gz @ z
        if self.Lz is None:
            lba, uba = self.lba0, self.uba0
        else:
            shift = self.Lz @ z
            lba, uba = self.lba0 + shift, self.uba0 + shift
        lbx, ubx = self.lbx, self.ubx
        if self.ix0.size or dv is not None:
            lbx, ubx = lbx.copy(), ubx.copy()
        if self.ix0.size:
            lbx[self.ix0] = z
            ubx[self.ix0] = z
        if dv is not None:
            lbx[self.moves] -= dv
            ubx[self.moves] -= dv
        if dc is not None and self.soft_rows.size:
            shift = np.hstack([dc, dc])
            lba, uba = lba.copy(), uba.copy()
            lba[self.soft_rows] -= shift
            uba[self.soft_rows] -= shift
        return g, lba, uba, lbx, ubx


def _shift_blocks(first: int, block: int, count: int, tail: np.ndarray) -> np.ndarray:
    """Indices of stage blocks shifted one stage earlier, the last stage repeated, then ``tail`` unchanged."""
    idx = [np.arange(first)]
    for k in range(count):
        src = min(k + 1, count - 1)
        idx.append(first + src * block + np.arange(block))
    idx.append(tail)
    return np.concatenate(idx).astype(int)


def sparse_qp(pb: ScaledProblem, soft_on_next: bool = False) -> QP:
    """Stage-wise sparse QP (see the module docstring); ``soft_on_next``: soft rows on ``A z_k + B v_k`` (HPIPM)."""
    n, m, ns, N = pb.n, pb.m, pb.ns, pb.horizon
    blk = n + m + ns
    nw = N * blk + n
    zi = lambda k: k * blk + np.arange(n)  # noqa: E731
    vi = lambda k: k * blk + n + np.arange(m)  # noqa: E731
    si = lambda k: k * blk + n + m + np.arange(ns)  # noqa: E731
    zN = N * blk + np.arange(n)
    # Hessian (upper triangle is enough for OSQP; give full symmetric for casadi)
    H = sp.lil_matrix((nw, nw))
    g0 = np.zeros(nw)
    for k in range(N):
        H[np.ix_(zi(k), zi(k))] = pb.Q
        H[np.ix_(vi(k), vi(k))] = pb.R
        if ns:
            H[np.ix_(si(k), si(k))] = pb.l2 * np.eye(ns)
            g0[si(k)] = pb.l1
    H[np.ix_(zN, zN)] = pb.P
    # rows per stage: dynamics (n) then 2 ns soft rows
    rblk = n + 2 * ns
    A = sp.lil_matrix((N * rblk, nw))
    lba, uba = np.zeros(N * rblk), np.zeros(N * rblk)
    for k in range(N):
        r = k * rblk
        dyn = r + np.arange(n)
        A[np.ix_(dyn, zi(k))] = pb.A
        A[np.ix_(dyn, vi(k))] = pb.B
        A[np.ix_(dyn, zN if k == N - 1 else zi(k + 1))] = -np.eye(n)
        if ns:
            lo, hi = r + n + np.arange(ns), r + n + ns + np.arange(ns)
            for rows, sign in ((hi, -1.0), (lo, 1.0)):
                if soft_on_next:
                    A[np.ix_(rows, zi(k))] = pb.C @ pb.A
                    A[np.ix_(rows, vi(k))] = pb.C @ pb.B
                else:
                    A[np.ix_(rows, zN if k == N - 1 else zi(k + 1))] = pb.C
                A[np.ix_(rows, si(k))] = sign * np.eye(ns)
            lba[hi], uba[hi] = -np.inf, pb.c_hi
            lba[lo], uba[lo] = pb.c_lo, np.inf
    lbx, ubx = np.full(nw, -np.inf), np.full(nw, np.inf)
    for k in range(N):
        lbx[vi(k)], ubx[vi(k)] = pb.v_lo, pb.v_hi
        if ns:
            lbx[si(k)] = 0.0
    shift_w = _shift_blocks(0, blk, N, zN)
    shift_a = _shift_blocks(0, rblk, N, np.zeros(0, int))
    stages = {"N": N, "nx": [n] * (N + 1), "nu": [m + ns] * N + [0], "ng": [2 * ns] * N + [0]}
    soft = np.array([k * rblk + n + np.arange(2 * ns) for k in range(N)], dtype=int).reshape(N, 2 * ns)
    return QP(sp.csc_matrix(H), g0, sp.csc_matrix(A), lba, uba, lbx, ubx, None, None, zi(0), vi(0),
              np.array([vi(k) for k in range(N)]), np.concatenate([si(k) for k in range(N)]) if ns else np.zeros(0, int),
              shift_w, shift_a, stages, n, soft)


def prediction_matrices(pb: ScaledProblem) -> tuple[np.ndarray, np.ndarray]:
    """``Phi`` (N n x n) and ``Gamma`` (N n x N m): ``[z_1..z_N] = Phi z_0 + Gamma v``."""
    n, m, N = pb.n, pb.m, pb.horizon
    Phi = np.zeros((N * n, n))
    Gam = np.zeros((N * n, N * m))
    Ak = np.eye(n)
    powers = []
    for k in range(N):
        powers.append(Ak)
        Ak = pb.A @ Ak
        Phi[k * n:(k + 1) * n] = Ak
    for k in range(N):
        for j in range(k + 1):
            Gam[k * n:(k + 1) * n, j * m:(j + 1) * m] = powers[k - j] @ pb.B
    return Phi, Gam


def condensed_qp(pb: ScaledProblem) -> QP:
    """Dense QP in ``[v, s]`` (see the module docstring)."""
    n, m, ns, N = pb.n, pb.m, pb.ns, pb.horizon
    Phi, Gam = prediction_matrices(pb)
    Qt = np.zeros((N * n, N * n))
    for k in range(N - 1):
        Qt[k * n:(k + 1) * n, k * n:(k + 1) * n] = pb.Q
    Qt[(N - 1) * n:, (N - 1) * n:] = pb.P
    Hv = Gam.T @ Qt @ Gam + np.kron(np.eye(N), pb.R)
    Fv = Gam.T @ Qt @ Phi
    nv, nsl = N * m, N * ns
    nw = nv + nsl
    H = np.zeros((nw, nw))
    H[:nv, :nv] = 0.5 * (Hv + Hv.T)
    H[nv:, nv:] = pb.l2 * np.eye(nsl)
    g0 = np.r_[np.zeros(nv), np.full(nsl, pb.l1)]
    Gz = np.vstack([Fv, np.zeros((nsl, n))])
    lbx = np.r_[np.tile(pb.v_lo, N), np.zeros(nsl)]
    ubx = np.r_[np.tile(pb.v_hi, N), np.full(nsl, np.inf)]
    if ns:
        Cb = np.kron(np.eye(N), pb.C)
        CG, CP = Cb @ Gam, Cb @ Phi
        Islack = np.eye(nsl)
        A = np.vstack([np.hstack([CG, -Islack]), np.hstack([CG, Islack])])
        lba0 = np.r_[np.full(nsl, -np.inf), np.tile(pb.c_lo, N)]
        uba0 = np.r_[np.tile(pb.c_hi, N), np.full(nsl, np.inf)]
        Lz = -np.vstack([CP, CP])
    else:
        A, lba0, uba0, Lz = np.zeros((0, nw)), np.zeros(0), np.zeros(0), None
    shift_v = _shift_blocks(0, m, N, np.zeros(0, int))
    shift_s = nv + _shift_blocks(0, ns, N, np.zeros(0, int)) if ns else np.zeros(0, int)
    shift_w = np.r_[shift_v, shift_s].astype(int)
    shift_a = np.r_[_shift_blocks(0, ns, N, np.zeros(0, int)), nsl + _shift_blocks(0, ns, N, np.zeros(0, int))].astype(int) \
        if ns else np.zeros(0, int)
    moves = np.arange(nv).reshape(N, m)
    soft = np.array([np.r_[k * ns + np.arange(ns), nsl + k * ns + np.arange(ns)] for k in range(N)],
                    dtype=int).reshape(N, 2 * ns)
    return QP(sp.csc_matrix(H), g0, sp.csc_matrix(A), lba0, uba0, lbx, ubx, Gz, Lz, np.zeros(0, int), moves[0], moves,
              nv + np.arange(nsl), shift_w, shift_a, {}, n, soft)


# --------------------------------------------------------------------------------------
# backends
# --------------------------------------------------------------------------------------
@dataclass
class Solution:
    ok: bool
    status: str
    w: np.ndarray
    iterations: int
    solve_time: float


class OSQPBackend:
    """OSQP with the variable bounds as extra rows; only ``q``/``l``/``u`` are ever updated."""

    name = "osqp"

    def __init__(self, qp: QP, settings, accept_inaccurate: bool, warm_start: str):
        import osqp

        self.qp = qp
        nw = qp.H.shape[0]
        has_bound = np.isfinite(qp.lbx) | np.isfinite(qp.ubx)
        has_bound[qp.ix0] = True  # the initial state is fixed by its bounds
        bounded = np.flatnonzero(has_bound)
        self.bounded = bounded
        box = sp.csc_matrix((np.ones(bounded.size), (np.arange(bounded.size), bounded)), shape=(bounded.size, nw))
        self.A = sp.vstack([qp.A, box], format="csc")
        self.n_rows = qp.A.shape[0]
        inv_pos = np.full(nw, -1)
        inv_pos[bounded] = np.arange(bounded.size)
        # dual shift: general rows by shift_a, box rows follow their variables
        box_shift = inv_pos[qp.shift_w[bounded]]
        self.shift_y = np.r_[qp.shift_a, self.n_rows + np.where(box_shift >= 0, box_shift, np.arange(bounded.size))].astype(int)
        self.accept = {1} | ({2} if accept_inaccurate else set())
        self.warm = warm_start
        opts = settings.as_dict()
        self.solver = osqp.OSQP()
        g, lba, uba, lbx, ubx = qp.vectors(np.zeros(qp.n_state))
        self.solver.setup(sp.triu(qp.H, format="csc"), g, self.A, np.r_[lba, lbx[bounded]], np.r_[uba, ubx[bounded]],
                          verbose=False, warm_starting=warm_start != "none", **opts)
        self.y = None

    def solve(self, z: np.ndarray, w_prev: np.ndarray | None, dv: np.ndarray | None = None,
              dc: np.ndarray | None = None) -> Solution:
        g, lba, uba, lbx, ubx = self.qp.vectors(z, dv, dc)
        self.solver.update(q=g, l=np.r_[lba, lbx[self.bounded]], u=np.r_[uba, ubx[self.bounded]])
        if self.warm == "shift" and w_prev is not None and self.y is not None:
            self.solver.warm_start(x=w_prev[self.qp.shift_w], y=self.y[self.shift_y])
        res = self.solver.solve(raise_error=False)
        status = res.info.status_val
        self.y = res.y
        ok = status in self.accept
        return Solution(ok, res.info.status, res.x, int(res.info.iter), float(res.info.run_time))


class ConicBackend:
    """A QP solver shipped with CasADi (``casadi.conic``): hpipm, daqp, qpoases, osqp."""

    def __init__(self, qp: QP, name: str, options: dict | None = None):
        self.qp = qp
        self.name = name
        opts = dict(options or {})
        if name == "hpipm":
            opts.update({key: qp.stages[key] for key in ("N", "nx", "nu", "ng")})
            opts.setdefault("hpipm", {"mode": "speed", "iter_max": 30, "res_g_max": 1e-5, "res_b_max": 1e-6,
                                      "res_d_max": 1e-6, "res_m_max": 1e-6})
        elif name == "qpoases":
            opts.setdefault("printLevel", "none")
            opts.setdefault("sparse", False)
        elif name == "osqp":
            opts.setdefault("osqp", {"verbose": False})
        opts.setdefault("error_on_fail", False)
        H = ca.DM(qp.H)
        A = ca.DM(qp.A) if qp.A.shape[0] else ca.DM(0, qp.H.shape[0])
        self.H, self.Am = H, A
        self.solver = ca.conic("mpc_qp", name, {"h": H.sparsity(), "a": A.sparsity()}, opts)

    def solve(self, z: np.ndarray, w_prev: np.ndarray | None, dv: np.ndarray | None = None,
              dc: np.ndarray | None = None) -> Solution:
        g, lba, uba, lbx, ubx = self.qp.vectors(z, dv, dc)
        args = {"h": self.H, "g": g, "a": self.Am, "lba": lba, "uba": uba, "lbx": lbx, "ubx": ubx}
        if w_prev is not None:
            args["x0"] = w_prev[self.qp.shift_w]
        out = self.solver(**args)
        stats = self.solver.stats()
        w = np.array(out["x"], dtype=float).ravel()
        ok = bool(stats.get("success", False)) and np.all(np.isfinite(w))
        status = "solved" if ok else str(stats.get("unified_return_status", stats.get("return_status", "failed")))
        return Solution(ok, status, w, int(stats.get("iter_count", -1) or -1),
                        float(stats.get("t_wall_solver", stats.get("t_wall_total", math.nan))))


# --------------------------------------------------------------------------------------
# controller
# --------------------------------------------------------------------------------------
class MPCController(Controller):
    """Linear MPC (see the module docstring)."""

    kind = "mpc"

    def __init__(self, settings: MPCSettings, plant: LinearPlant, limits: np.ndarray, problem: ScaledProblem,
                 qp: QP, backend, observer):
        super().__init__(settings, plant.op, plant.sensors, limits, saturate=True)
        self.plant = plant
        self.problem = problem
        self.qp = qp
        self.backend = backend
        self.observer = observer
        self._w: np.ndarray | None = None  # last solution
        self._plan: np.ndarray | None = None  # (N, m) scaled moves of the last solution
        self._plan_u: np.ndarray | None = None  # (N, m) planned torques, N m
        self._age = 0
        self.last: Solution | None = None

    @property
    def K(self) -> np.ndarray:
        """LQR gain in physical units (``du = -K dx``)."""
        pb = self.problem
        return pb.Su[:, None] * pb.K / pb.Sx[None, :]

    def linear_law(self, q_joints) -> tuple[np.ndarray, ...]:
        """The unconstrained law (the LQR move ``-K dx`` on the estimate), as :meth:`LQRController.linear_law`."""
        E, F, G = self.observer.linear_form(self.sensors.n_y, self.n_u)
        return E, F, G, -self.K, np.zeros((self.n_u, self.sensors.n_y))

    def _reset(self) -> None:
        self.observer.reset()
        self._w = None
        self._plan = None
        self._plan_u = None
        self._age = 0

    def plan(self) -> np.ndarray | None:
        """Planned torques (N m) of the last solved QP, shape (N, n_u)."""
        return None if self._plan_u is None else self._plan_u.copy()

    def reference_shifts(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Scaled reference over the horizon from ``t``: ``(r (N+1, n), u_ref (N, m) in N m, dv (N, m), dc (N, ns))``.

        ``r_k = (x_ref,k - x_op) / S_x``; ``dv``, ``dc`` shift the input and soft-row bounds.
        """
        pb = self.problem
        X, U, _ = self.reference.window(t, self.sample_time, pb.horizon + 1)
        r = (X - self.op.x) / pb.Sx
        dv = (U[:-1] - self.op.u) / pb.Su
        dc = r[1:] @ pb.C.T if pb.ns else np.zeros((pb.horizon, 0))
        return r, U[:-1], dv, dc

    def solve(self, x: np.ndarray, t: float = 0.0) -> Solution:
        """Solve the QP for state ``x`` (absolute) at time ``t`` (s) and return the raw :class:`Solution`.

        For inspection: the plan and the statistics are not updated (OSQP's internal
        warm start is).
        """
        r, _u, dv, dc = self.reference_shifts(t)
        z = (x - self.op.x) / self.problem.Sx - r[0]
        warm = self._w if self.settings.warm_start != "none" else None
        return self.backend.solve(z, warm, dv, dc)

    def _step(self, t: float, y: np.ndarray) -> np.ndarray:
        x = self.observer.estimate(y, self.u_previous)
        r, u_ref, dv, dc = self.reference_shifts(t)
        z = (x - self.op.x) / self.problem.Sx - r[0]
        sol = self.backend.solve(z, self._w if self.settings.warm_start != "none" else None, dv, dc)
        self.last = sol
        self.stats.iterations.append(sol.iterations)
        if sol.ok:
            self.record(sol.status or "solved")
            self._w = sol.w
            self._plan = sol.w[self.qp.moves]
            self._plan_u = u_ref + self._plan * self.problem.Su
            self._age = 0
            if self.qp.slack.size:
                self.stats.slack_max = max(self.stats.slack_max, float(np.max(sol.w[self.qp.slack])) * self.problem.h)
            return self._plan_u[0].copy()
        self._age += 1
        fb = self.settings.fallback
        if fb == "shift" and self._plan_u is not None and self._age < self.problem.horizon:
            u = self._plan_u[self._age].copy()
            used = "shift"
        elif fb == "hold":
            self.fallback(t, sol.status, "hold")
            return self.u_previous.copy()
        else:
            u = u_ref[0] + self.problem.Su * (-self.problem.K @ z)
            used = "lqr"
        self.fallback(t, sol.status, used)
        if self._w is not None:
            self._w = self._w[self.qp.shift_w]  # keep warm starts moving with time
        return u


def make_backend(qp: QP, settings: MPCSettings):
    """The QP backend named by ``settings.backend``."""
    if settings.backend == "osqp":
        return OSQPBackend(qp, settings.osqp, settings.accept_inaccurate, settings.warm_start)
    return ConicBackend(qp, settings.backend)


def design_mpc(model, op: OperatingPoint, settings: MPCSettings) -> MPCController:
    """Build the linear MPC regulating ``model`` to ``op`` (the QP and its solver workspace, once)."""
    limits = torque_limits(model)
    sensors = build_sensors(model, settings.sensors, op)
    plant = linear_plant(model, op, sensors, settings.sample_time)
    problem = scaled_problem(model, plant, settings, limits)
    if settings.formulation == "sparse":
        qp = sparse_qp(problem, soft_on_next=settings.backend == "hpipm")
    else:
        qp = condensed_qp(problem)
    backend = make_backend(qp, settings)
    observer = make_observer(model, op, sensors, plant.sys.A, plant.sysd, settings.estimator)
    return MPCController(settings, plant, limits, problem, qp, backend, observer)


__all__ = ["MPCController", "design_mpc", "ScaledProblem", "QP", "sparse_qp", "condensed_qp", "scaled_problem",
           "prediction_matrices", "OSQPBackend", "ConicBackend", "Solution", "state_scales"]
