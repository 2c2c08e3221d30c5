"""Nonlinear MPC in CasADi on the full model: multiple shooting with RK4, real-time iteration or full NLP.

Variables are the scaled deviations of :mod:`flexctrl.control.mpc` (same scales,
weights, DARE terminal cost, torque bounds and soft constraints), stage-wise::

    w = [z_0, v_0, s_0, z_1, v_1, s_1, ..., z_N]

Shooting map ``F``: ``substeps`` classical RK4 steps of the model's ``f(x, u)``
over one sample (``f`` is called, not inlined, so generated code holds it once).

Real-time iteration (``mode = "rti"``, default): one Gauss-Newton SQP step per
sample.  One CasADi Function, ``linearize(Z, V) -> (F, A, B)`` mapped over the N
intervals (``Function.map``, compiled to C when ``compile``), gives the shooting
ends and their Jacobians along the previous (shifted) trajectory; a second CasADi
Function assembles the QP (fixed sparsity) and ``casadi.conic`` (HPIPM by default:
Riccati-structured interior point) solves it::

    min 1/2 w'Hw + g'w   s.t.  A_k z_k + B_k v_k - z_{k+1} = A_k zb_k + B_k vb_k - F(zb_k, vb_k)
                               soft rows on C z_{k+1}, torque bounds, z_0 = z(t)

The QP solution is the new trajectory (full step).  With ``sensitivities = "frozen"``
``A_k, B_k`` are the exact transition matrices of RK4 applied to the dynamics
linearised at ``(zb_k, vb_k)`` (one Jacobian of ``f`` per interval): an inexact-Jacobian
SQP whose fixed points still satisfy the nonlinear shooting equations, since the gaps
use the nonlinear ``F``.  ``"exact"`` propagates the Jacobian of ``f`` through every RK4
stage (4 ``substeps`` Jacobians per interval).

A moving reference (:mod:`flexctrl.control.reference`) enters only the linear cost,
``g = g0 - H w_ref`` with ``w_ref`` the scaled reference states and feed-forward torques
over the horizon: the stage costs penalise deviations from the reference while the
shooting constraints stay the nonlinear model (no reference consistency is assumed).

The soft rows use the output map linearised at the target; for the assumed-modes
models the link tip deflections are linear in the elastic coordinates, so the
deflection constraint is exact.

Full NLP (``mode = "full"``): the same problem with the nonlinear shooting
constraints, solved by IPOPT (limited-memory Hessian), warm-started from the shifted
previous solution; it is an offline reference (tens of seconds per solve on the
18-state arm with CasADi's virtual machine).  FATROP, which ships with CasADi, was
tried with the same stage-wise NLP: its structure detection accepted it but the
solver raised at its first iteration (return flag 11, CasADi 3.8), so only IPOPT is
offered.  The first sample after :meth:`reset` starts from the nonlinear
rollout under the (saturated) LQR law, optionally improved by ``init_iter`` IPOPT
iterations.
"""

from __future__ import annotations

import math
import time

import casadi as ca
import numpy as np

from flexctrl.control.base import Controller
from flexctrl.control.estimator import make_observer
from flexctrl.control.lqr import LinearPlant, build_sensors, linear_plant
from flexctrl.control.mpc import ScaledProblem, Solution, _shift_blocks, scaled_problem
from flexctrl.control.settings import NMPCSettings
from flexctrl.linear import OperatingPoint, torque_limits

#: RK4 step bound ``|lambda|_max h`` used to choose the substeps (stability limit 2.83 on the imaginary axis).
RK4_BOUND = 2.5


def auto_substeps(plant: LinearPlant) -> int:
    """Fewest RK4 steps per sample with ``|lambda|_max h <= RK4_BOUND`` for the linearisation at the target."""
    lam = float(np.max(np.abs(np.linalg.eigvals(np.asarray(plant.sys.A, dtype=float)))))
    return max(1, int(math.ceil(lam * plant.dt / RK4_BOUND)))


def _expanded(fun: ca.Function) -> ca.Function:
    try:
        return fun if fun.is_a("SXFunction") else fun.expand()
    except RuntimeError:
        return fun


def interval_functions(model, dt: float, substeps: int, sensitivities: str) -> tuple[ca.Function, ca.Function]:
    """``F(x, u) -> x_next`` and ``FJ(x, u) -> (x_next, A, B)`` over one sample, physical units."""
    nx, nu = model.n_x, model.n_u
    f = _expanded(model.functions["f"])
    xs, us = ca.SX.sym("x", nx), ca.SX.sym("u", nu)
    fx = ca.Function("f_jac", [xs, us], [f(xs, us), ca.jacobian(f(xs, us), xs), ca.jacobian(f(xs, us), us)],
                     ["x", "u"], ["xdot", "A", "B"], {"cse": True})
    x, u = ca.MX.sym("x", nx), ca.MX.sym("u", nu)
    h = dt / substeps
    xe = x
    for _ in range(substeps):
        k1 = f(xe, u)
        k2 = f(xe + 0.5 * h * k1, u)
        k3 = f(xe + 0.5 * h * k2, u)
        k4 = f(xe + h * k3, u)
        xe = xe + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
    F = ca.Function("F", [x, u], [xe], ["x", "u"], ["x_next"])
    eye = ca.DM.eye(nx)
    if sensitivities == "frozen":
        _xd, Jx, Ju = fx(x, u)
        hA = h * Jx
        hA2 = ca.mtimes(hA, hA)
        hA3 = ca.mtimes(hA2, hA)
        Phi = eye + hA + hA2 / 2 + hA3 / 6 + ca.mtimes(hA3, hA) / 24
        Gam = h * ca.mtimes(eye + hA / 2 + hA2 / 6 + hA3 / 24, Ju)
        Ad, Bd = eye, ca.MX.zeros(nx, nu)
        for _ in range(substeps):
            Ad, Bd = ca.mtimes(Phi, Ad), ca.mtimes(Phi, Bd) + Gam
    else:
        xe, Ad, Bd = x, eye, ca.MX.zeros(nx, nu)
        for _ in range(substeps):
            k1, J1x, J1u = fx(xe, u)
            x2 = xe + 0.5 * h * k1
            k2, J2x, J2u = fx(x2, u)
            x3 = xe + 0.5 * h * k2
            k3, J3x, J3u = fx(x3, u)
            x4 = xe + h * k3
            k4, J4x, J4u = fx(x4, u)
            dk1x, dk1u = ca.mtimes(J1x, Ad), ca.mtimes(J1x, Bd) + J1u
            dk2x = ca.mtimes(J2x, Ad + 0.5 * h * dk1x)
            dk2u = ca.mtimes(J2x, Bd + 0.5 * h * dk1u) + J2u
            dk3x = ca.mtimes(J3x, Ad + 0.5 * h * dk2x)
            dk3u = ca.mtimes(J3x, Bd + 0.5 * h * dk2u) + J3u
            dk4x = ca.mtimes(J4x, Ad + h * dk3x)
            dk4u = ca.mtimes(J4x, Bd + h * dk3u) + J4u
            xe = xe + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
            Ad = Ad + (h / 6.0) * (dk1x + 2 * dk2x + 2 * dk3x + dk4x)
            Bd = Bd + (h / 6.0) * (dk1u + 2 * dk2u + 2 * dk3u + dk4u)
        FJ = ca.Function("FJ", [x, u], [xe, Ad, Bd], ["x", "u"], ["x_next", "A", "B"])
        return F, FJ
    FJ = ca.Function("FJ", [x, u], [F(x, u), Ad, Bd], ["x", "u"], ["x_next", "A", "B"])
    return F, FJ


class _Layout:
    """Index bookkeeping of ``w = [z_0, v_0, s_0, ..., z_N]``."""

    def __init__(self, n: int, m: int, ns: int, N: int):
        self.n, self.m, self.ns, self.N = n, m, ns, N
        self.blk = n + m + ns
        self.nw = N * self.blk + n
        self.z = np.array([k * self.blk + np.arange(n) for k in range(N)] + [N * self.blk + np.arange(n)])
        self.v = np.array([k * self.blk + n + np.arange(m) for k in range(N)])
        self.s = np.array([k * self.blk + n + m + np.arange(ns) for k in range(N)]).reshape(N, ns)
        self.shift = _shift_blocks(0, self.blk, N, N * self.blk + np.arange(n))

    def split(self, w):
        """(Z (n x N+1), V (m x N), S (ns x N)) of a symbolic or numeric ``w``."""
        head = ca.reshape(w[: self.N * self.blk], self.blk, self.N)
        Z = ca.horzcat(head[: self.n, :], w[self.N * self.blk:])
        return Z, head[self.n:self.n + self.m, :], head[self.n + self.m:, :]


class NMPCController(Controller):
    """Nonlinear MPC (see the module docstring)."""

    kind = "nmpc"

    def __init__(self, settings: NMPCSettings, plant: LinearPlant, limits: np.ndarray, problem: ScaledProblem,
                 observer, functions: dict, layout: _Layout, substeps: int, compiled: bool):
        super().__init__(settings, plant.op, plant.sensors, limits, saturate=True)
        self.plant = plant
        self.problem = problem
        self.observer = observer
        self.functions = functions
        self.layout = layout
        self.substeps = substeps
        self.compiled = compiled
        self._w: np.ndarray | None = None
        self._plan: np.ndarray | None = None
        self._age = 0
        self.last: Solution | None = None
        self.timing: dict[str, list[float]] = {"linearize_qp": [], "qp": [], "total": []}
        self._reference_now = (np.zeros(problem.n), np.zeros(problem.m))

    def _reset(self) -> None:
        self.observer.reset()
        self._w = None
        self._plan = None
        self._age = 0
        self.timing = {"linearize_qp": [], "qp": [], "total": []}

    # -- pieces ------------------------------------------------------------------------
    def initial_guess(self, z0: np.ndarray) -> np.ndarray:
        """Nonlinear rollout from ``z0`` under the saturated LQR law, as ``w``."""
        Z, V = (np.array(a, dtype=float) for a in self.functions["rollout"](z0))
        lay = self.layout
        w = np.zeros(lay.nw)
        w[lay.z[0]] = z0
        for k in range(lay.N):
            w[lay.z[k + 1]] = Z[:, k]
            w[lay.v[k]] = V[:, k]
        return w

    def cost_vector(self, t: float) -> np.ndarray:
        """Linear cost ``g = g0 - H w_ref`` of the reference over the horizon from ``t`` (s).

        ``w_ref`` holds the scaled reference states ``(x_ref,k - x_op) / S_x`` and inputs
        ``(u_ref,k - u_op) / S_u``, so the stage costs penalise deviations from the
        reference (:mod:`flexctrl.control.reference`); ``g0`` for a reference at ``op``.
        """
        lay, pb = self.layout, self.problem
        X, U, _ = self.reference.window(t, self.sample_time, lay.N + 1)
        w_ref = np.zeros(lay.nw)
        for k in range(lay.N + 1):
            w_ref[lay.z[k]] = (X[k] - self.op.x) / pb.Sx
        for k in range(lay.N):
            w_ref[lay.v[k]] = (U[k] - self.op.u) / pb.Su
        self._reference_now = (w_ref[lay.z[0]], w_ref[lay.v[0]])
        return self.functions["g0"] - self.functions["Hnp"] @ w_ref

    def _nlp(self, z0: np.ndarray, w0: np.ndarray, max_iter: int, g: np.ndarray | None = None) -> Solution:
        solver = self.functions["nlp"]
        lbx, ubx = self.functions["bounds"](z0)
        start = time.perf_counter()
        g = self.functions["g0"] if g is None else g
        out = solver(x0=w0, p=np.r_[z0, g], lbx=lbx, ubx=ubx, lbg=self.functions["lbg"], ubg=self.functions["ubg"])
        stats = solver.stats()
        w = np.array(out["x"], dtype=float).ravel()
        ok = bool(stats.get("success", False)) or (stats.get("return_status") == "Maximum_Iterations_Exceeded"
                                                    and max_iter < self.settings.max_iter)
        return Solution(ok and bool(np.all(np.isfinite(w))), str(stats.get("return_status", "")), w,
                        int(stats.get("iter_count", -1)), time.perf_counter() - start)

    def _rti(self, z0: np.ndarray, w0: np.ndarray, g: np.ndarray | None = None) -> Solution:
        start = time.perf_counter()
        a, lba, uba = self.functions["prepare"](z0, w0)
        lbx, ubx = self.functions["bounds"](z0)
        mid = time.perf_counter()
        qp = self.functions["qp"]
        g = self.functions["g0"] if g is None else g
        out = qp(h=self.functions["H"], g=g, a=a, lba=lba, uba=uba, lbx=lbx, ubx=ubx, x0=w0)
        end = time.perf_counter()
        stats = qp.stats()
        w = np.array(out["x"], dtype=float).ravel()
        self.timing["linearize_qp"].append(mid - start)
        self.timing["qp"].append(end - mid)
        ok = bool(stats.get("success", False)) and bool(np.all(np.isfinite(w)))
        status = "solved" if ok else str(stats.get("unified_return_status", stats.get("return_status", "failed")))
        return Solution(ok, status, w, int(stats.get("iter_count", -1) or -1), end - start)

    def solve(self, x: np.ndarray, t: float = 0.0) -> Solution:
        """One NMPC solve (RTI step or NLP) for the state ``x`` (absolute) at ``t`` (s), updating the warm start."""
        z0 = (x - self.op.x) / self.problem.Sx
        g = self.cost_vector(t)
        if self._w is None:
            w0 = self.initial_guess(z0)
            if self.settings.mode == "rti" and self.settings.init_iter > 0:
                init = self._nlp(z0, w0, self.settings.init_iter, g)
                if np.all(np.isfinite(init.w)):
                    w0 = init.w
        else:
            w0 = self._w[self.layout.shift]
            w0[self.layout.z[0]] = z0
        return self._nlp(z0, w0, self.settings.max_iter, g) if self.settings.mode == "full" else self._rti(z0, w0, g)

    def _step(self, t: float, y: np.ndarray) -> np.ndarray:
        start = time.perf_counter()
        x = self.observer.estimate(y, self.u_previous)
        z0 = (x - self.op.x) / self.problem.Sx
        sol = self.solve(x, t)
        self.last = sol
        self.stats.iterations.append(sol.iterations)
        lay = self.layout
        if sol.ok:
            self.record("solved")
            self._w = sol.w
            self._plan = sol.w[lay.v]
            self._age = 0
            if lay.ns:
                self.stats.slack_max = max(self.stats.slack_max, float(np.max(sol.w[lay.s])) * self.problem.h)
            v = self._plan[0]
        else:
            self._age += 1
            if self._plan is not None and self._age < lay.N:
                v = self._plan[self._age]
                used = "shift"
                self._w = self._w[lay.shift]  # keep warm starts moving with time
            else:
                z_ref, v_ref = self._reference_now
                v = np.clip(v_ref - self.problem.K @ (z0 - z_ref), self.problem.v_lo, self.problem.v_hi)
                used = "lqr"
                self._w = None
                self._plan = None
            self.fallback(t, sol.status, used)
        self.timing["total"].append(time.perf_counter() - start)
        return self.op.u + self.problem.Su * v


def _build(model, plant: LinearPlant, settings: NMPCSettings, pb: ScaledProblem, substeps: int):
    """The CasADi Functions of the NMPC (see the module docstring)."""
    n, m, ns, N = pb.n, pb.m, pb.ns, pb.horizon
    lay = _Layout(n, m, ns, N)
    F, FJ = interval_functions(model, plant.dt, substeps, settings.sensitivities)
    xop, uop = ca.DM(plant.op.x), ca.DM(plant.op.u)
    Sx, Su = ca.DM(pb.Sx), ca.DM(pb.Su)
    # scaled interval map, mapped over the horizon
    z, v = ca.MX.sym("z", n), ca.MX.sym("v", m)
    xn, Ad, Bd = FJ(xop + Sx * z, uop + Su * v)
    Fs = (xn - xop) / Sx
    As = ca.mtimes(ca.diag(1 / Sx), ca.mtimes(Ad, ca.diag(Sx)))
    Bs = ca.mtimes(ca.diag(1 / Sx), ca.mtimes(Bd, ca.diag(Su)))
    lin = ca.Function("nmpc_interval", [z, v], [Fs, As, Bs], ["z", "v"], ["F", "A", "B"])
    linmap = lin.map(N)
    compiled = False
    if settings.compile:
        from flexctrl.sim.compile import compile_function

        result = compile_function(linmap)
        linmap, compiled = result.function, result.compiled
    Fz = ca.Function("nmpc_F", [z, v], [(F(xop + Sx * z, uop + Su * v) - xop) / Sx])
    # QP assembly: one Function of (z0, w)
    z0 = ca.MX.sym("z0", n)
    w = ca.MX.sym("w", lay.nw)
    Z, V, _S = lay.split(w)
    Fk, Ak, Bk = linmap(Z[:, :N], V)
    C = ca.DM(pb.C)
    rows, lba, uba = [], [], []
    for k in range(N):
        A_k = Ak[:, k * n:(k + 1) * n]
        B_k = Bk[:, k * m:(k + 1) * m]
        b_k = ca.mtimes(A_k, Z[:, k]) + ca.mtimes(B_k, V[:, k]) - Fk[:, k]
        left = k * lay.blk
        right = lay.nw - left - lay.blk - n
        dyn = ca.horzcat(ca.MX(n, left), A_k, B_k, ca.MX(n, ns), -ca.MX.eye(n), ca.MX(n, right))
        rows.append(dyn)
        lba.append(b_k)
        uba.append(b_k)
        if ns:
            CA, CB = ca.mtimes(C, A_k), ca.mtimes(C, B_k)
            Cb = ca.mtimes(C, b_k)
            I_s = ca.MX.eye(ns)
            for sign, lo, hi in ((-1.0, -ca.inf * ca.DM.ones(ns), ca.DM(pb.c_hi) + Cb),
                                 (1.0, ca.DM(pb.c_lo) + Cb, ca.inf * ca.DM.ones(ns))):
                rows.append(ca.horzcat(ca.MX(ns, left), CA, CB, sign * I_s, ca.MX(ns, n + right)))
                lba.append(lo)
                uba.append(hi)
    Aqp = ca.vertcat(*rows)
    prepare = ca.Function("nmpc_prepare", [z0, w], [Aqp, ca.vertcat(*lba), ca.vertcat(*uba)], ["z0", "w"],
                          ["a", "lba", "uba"])
    # bounds, cost
    lbx0, ubx0 = np.full(lay.nw, -np.inf), np.full(lay.nw, np.inf)
    for k in range(N):
        lbx0[lay.v[k]], ubx0[lay.v[k]] = pb.v_lo, pb.v_hi
        if ns:
            lbx0[lay.s[k]] = 0.0
    zz = ca.MX.sym("z0", n)
    lbx_e = ca.MX(ca.DM(lbx0))
    ubx_e = ca.MX(ca.DM(ubx0))
    lbx_e[lay.z[0].tolist()] = zz
    ubx_e[lay.z[0].tolist()] = zz
    bounds = ca.Function("nmpc_bounds", [zz], [lbx_e, ubx_e])
    H = np.zeros((lay.nw, lay.nw))
    g = np.zeros(lay.nw)
    for k in range(N):
        H[np.ix_(lay.z[k], lay.z[k])] = pb.Q
        H[np.ix_(lay.v[k], lay.v[k])] = pb.R
        if ns:
            H[np.ix_(lay.s[k], lay.s[k])] = pb.l2 * np.eye(ns)
            g[lay.s[k]] = pb.l1
    H[np.ix_(lay.z[N], lay.z[N])] = pb.P
    Hs = ca.DM(H)
    Hs = ca.DM(ca.sparsify(Hs))
    opts: dict = {"error_on_fail": False}
    a_sp = prepare.sparsity_out(0)
    if settings.qp_solver == "hpipm":
        opts.update({"N": N, "nx": [n] * (N + 1), "nu": [m + ns] * N + [0], "ng": [2 * ns] * N + [0],
                     "hpipm": {"mode": "speed", "iter_max": 30, "res_g_max": 1e-5, "res_b_max": 1e-6,
                               "res_d_max": 1e-6, "res_m_max": 1e-6}})
    elif settings.qp_solver == "qpoases":
        opts.update({"printLevel": "none", "sparse": True})
    elif settings.qp_solver == "osqp":
        opts.update({"osqp": {"verbose": False, "eps_abs": 1e-5, "eps_rel": 1e-5, "max_iter": 4000, "polishing": True}})
    qp = ca.conic("nmpc_qp", settings.qp_solver, {"h": Hs.sparsity(), "a": a_sp}, opts)
    # rollout under saturated LQR (initial guess)
    zr = ca.MX.sym("z", n)
    vr = ca.fmin(ca.fmax(-ca.mtimes(ca.DM(pb.K), zr), ca.DM(pb.v_lo)), ca.DM(pb.v_hi))
    step = ca.Function("nmpc_lqr_step", [zr], [Fz(zr, vr), vr])
    rollout = _rollout(step, N, n, m)
    import scipy.sparse as sp

    functions = {"prepare": prepare, "bounds": bounds, "qp": qp, "H": Hs, "g0": g, "Hnp": sp.csr_matrix(H),
                 "rollout": rollout,
                 "linmap": linmap, "F": Fz}
    # full NLP (also the RTI initialisation)
    if settings.mode == "full" or settings.init_iter > 0:
        functions.update(_nlp_functions(settings, pb, lay, Fz, H, g))
    return functions, lay, compiled


def _rollout(step: ca.Function, N: int, n: int, m: int) -> ca.Function:
    z0 = ca.MX.sym("z0", n)
    Z, V = [], []
    z = z0
    for _ in range(N):
        z, vk = step(z)
        Z.append(z)
        V.append(vk)
    return ca.Function("nmpc_rollout", [z0], [ca.horzcat(*Z), ca.horzcat(*V)])


def _nlp_functions(settings: NMPCSettings, pb: ScaledProblem, lay: _Layout, Fz: ca.Function, H: np.ndarray,
                   g: np.ndarray) -> dict:
    N, n, ns = lay.N, lay.n, lay.ns
    w = ca.MX.sym("w", lay.nw)
    p = ca.MX.sym("p", n + lay.nw)  # the initial state, then the linear cost (the reference enters there)
    Z, V, S = lay.split(w)
    Fmap = Fz.map(N)
    ends = Fmap(Z[:, :N], V)
    # stage-wise order: gap_k, then the soft rows of stage k written on F(z_k, v_k) (= z_{k+1})
    cons, lbg, ubg = [], [], []
    C = ca.DM(pb.C)
    for k in range(N):
        cons.append(ends[:, k] - Z[:, k + 1])
        lbg.append(np.zeros(n))
        ubg.append(np.zeros(n))
        if ns:
            CF = ca.mtimes(C, ends[:, k])
            cons += [CF - S[:, k], CF + S[:, k]]
            lbg += [np.full(ns, -np.inf), pb.c_lo]
            ubg += [pb.c_hi, np.full(ns, np.inf)]
    cost = 0.5 * ca.bilin(ca.DM(ca.sparsify(ca.DM(H))), w, w) + ca.dot(p[n:], w)
    nlp = {"x": w, "p": p, "f": cost, "g": ca.vertcat(*cons)}
    opts = {"ipopt": {"print_level": 0, "max_iter": settings.max_iter, "hessian_approximation": "limited-memory",
                      "warm_start_init_point": "yes", "tol": 1e-6, "sb": "yes"},
            "print_time": False, "error_on_fail": False}
    solver = ca.nlpsol("nmpc_nlp", settings.nlp_solver, nlp, opts)
    return {"nlp": solver, "lbg": np.concatenate(lbg), "ubg": np.concatenate(ubg)}


def design_nmpc(model, op: OperatingPoint, settings: NMPCSettings) -> NMPCController:
    """Build the nonlinear MPC regulating ``model`` to ``op`` (CasADi Functions and solvers, once)."""
    limits = torque_limits(model)
    sensors = build_sensors(model, settings.sensors, op)
    plant = linear_plant(model, op, sensors, settings.sample_time)
    problem = scaled_problem(model, plant, settings, limits)
    substeps = settings.substeps or auto_substeps(plant)
    functions, layout, compiled = _build(model, plant, settings, problem, substeps)
    observer = make_observer(model, op, sensors, plant.sys.A, plant.sysd, settings.estimator)
    return NMPCController(settings, plant, limits, problem, observer, functions, layout, substeps, compiled)


__all__ = ["NMPCController", "design_nmpc", "interval_functions", "auto_substeps", "RK4_BOUND"]
