"""The NMPC's first guess and its full NLP (IPOPT).

:func:`lqr_rollout` chains the saturated-LQR step of the scaled shooting map over the
horizon (the first guess after a reset or a failure); :func:`nlp_functions` builds the
stage-wise NLP of ``mode = "full"`` (and the RTI's ``init_iter``) on the same variables as the
RTI's QP (:mod:`flexctrl.control.nmpc.controller`'s module docstring), and :func:`solve_nlp`
solves it from a guess.  The full NLP is an offline reference: IPOPT with a limited-memory
Hessian, warm-started from the shifted previous solution.
"""

from __future__ import annotations

import time
from typing import Any

import casadi as ca
import numpy as np

from flexctrl.control.mpc.problem import ScaledProblem
from flexctrl.control.mpc.qp_backends import Solution
from flexctrl.spec.controller_settings import NMPCSettings


def lqr_rollout(step: ca.Function, N: int, n: int, m: int) -> ca.Function:
    """``rollout(z0, Z_ref, V_ref) -> (Z, V)``: ``N`` closed-loop steps of ``step``.

    Parameters
    ----------
    step : casadi.Function
        ``step(z, z_ref, v_ref) -> (z_next, v)``: one sample of the scaled shooting map under
        the saturated LQR law.
    N, n, m : int
        Samples, states and inputs.

    Returns
    -------
    casadi.Function
        ``Z`` (n x N) are ``z_1 .. z_N``, ``V`` (m x N) the moves.
    """
    z0 = ca.MX.sym("z0", n)
    Zr, Vr = ca.MX.sym("Z_ref", n, N), ca.MX.sym("V_ref", m, N)
    Z, V = [], []
    z = z0
    for k in range(N):
        z, vk = step(z, Zr[:, k], Vr[:, k])
        Z.append(z)
        V.append(vk)
    return ca.Function("nmpc_rollout", [z0, Zr, Vr], [ca.horzcat(*Z), ca.horzcat(*V)])


def nlp_functions(
    settings: NMPCSettings, pb: ScaledProblem, lay, Fz: ca.Function, H: np.ndarray, g: np.ndarray
) -> dict:
    """IPOPT on ``min 1/2 w'Hw + p_g'w`` s.t. the nonlinear shooting equations and soft rows.

    Parameters
    ----------
    settings : NMPCSettings
        Its ``max_iter`` and ``nlp_solver``.
    pb : ScaledProblem
        The soft rows ``C`` and their bounds.
    lay : flexctrl.control.nmpc.casadi_functions.Layout
        The variables' layout (the RTI's QP's).
    Fz : casadi.Function
        The scaled shooting map ``Fz(z, v) -> z_next``.
    H, g : ndarray
        The QP's Hessian and linear cost.

    Returns
    -------
    dict
        ``{"nlp", "lbg", "ubg"}``: the solver, whose parameter ``p`` is the scaled initial
        state followed by the linear cost, and the constraint rows' bounds.
    """
    N, n, ns = lay.N, lay.n, lay.ns
    w = ca.MX.sym("w", lay.nw)
    # the initial state, then the linear cost (the reference enters there)
    p = ca.MX.sym("p", n + lay.nw)
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
    opts: dict[str, Any] = {
        "ipopt": {
            "print_level": 0,
            "max_iter": settings.max_iter,
            "hessian_approximation": "limited-memory",
            "warm_start_init_point": "yes",
            "tol": 1e-6,
            "sb": "yes",
        },
        "print_time": False,
        "error_on_fail": False,
    }
    solver = ca.nlpsol("nmpc_nlp", settings.nlp_solver, nlp, opts)
    return {"nlp": solver, "lbg": np.concatenate(lbg), "ubg": np.concatenate(ubg)}


def solve_nlp(
    functions: dict,
    z0: np.ndarray,
    w0: np.ndarray,
    g: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray],
    max_iter: int,
    settings: NMPCSettings,
) -> Solution:
    """Solve the full NLP from ``w0`` (at most ``max_iter`` iterations).

    Parameters
    ----------
    functions : dict
        The NMPC's Functions with ``"nlp"``, ``"lbg"``, ``"ubg"`` (:func:`nlp_functions`).
    z0 : ndarray
        The scaled initial state.
    w0 : ndarray
        The first guess.
    g : ndarray
        The linear cost.
    bounds : tuple of ndarray
        ``(lbx, ubx)``, the variables' bounds.
    max_iter : int
        The iteration limit of this call: below ``settings.max_iter`` (the RTI's
        ``init_iter``), reaching it still counts as a solution.
    settings : NMPCSettings
        Its ``max_iter``.

    Returns
    -------
    Solution
        IPOPT's answer, its return status and iteration count.
    """
    solver = functions["nlp"]
    lbx, ubx = bounds
    start = time.perf_counter()
    out = solver(
        x0=w0, p=np.r_[z0, g], lbx=lbx, ubx=ubx, lbg=functions["lbg"], ubg=functions["ubg"]
    )
    stats = solver.stats()
    w = np.array(out["x"], dtype=float).ravel()
    ok = bool(stats.get("success", False)) or (
        stats.get("return_status") == "Maximum_Iterations_Exceeded" and max_iter < settings.max_iter
    )
    return Solution(
        ok and bool(np.all(np.isfinite(w))),
        str(stats.get("return_status", "")),
        w,
        int(stats.get("iter_count", -1)),
        time.perf_counter() - start,
    )


__all__ = ["lqr_rollout", "nlp_functions", "solve_nlp"]
