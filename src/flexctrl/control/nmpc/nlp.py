"""The NMPC's offline pieces: the initial guess's rollout and the full NLP (IPOPT).

:func:`lqr_rollout` chains the saturated-LQR step of the scaled shooting map over the
horizon (the RTI's first guess); :func:`nlp_functions` builds the stage-wise NLP of
``mode = "full"`` (and the RTI's ``init_iter``) on the same variables as the RTI's QP
(:mod:`flexctrl.control.nmpc.controller`'s module docstring).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from flexctrl.control.mpc.problem import ScaledProblem
from flexctrl.spec.controller_settings import NMPCSettings


def lqr_rollout(step: ca.Function, N: int, n: int, m: int) -> ca.Function:
    """``rollout(z0, Z_ref, V_ref) -> (Z, V)``: ``N`` closed-loop steps of ``step(z, z_ref, v_ref)``."""
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
    """``{"nlp", "lbg", "ubg"}``: IPOPT on ``min 1/2 w'Hw + p_g'w`` s.t. the nonlinear shooting and
    soft rows.

    ``lay`` is the QP's layout (``nmpc._Layout``), ``Fz`` the scaled shooting map; the
    parameter ``p`` is the scaled initial state followed by the linear cost.
    """
    N, n, ns = lay.N, lay.n, lay.ns
    w = ca.MX.sym("w", lay.nw)
    p = ca.MX.sym(
        "p", n + lay.nw
    )  # the initial state, then the linear cost (the reference enters there)
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
    opts = {
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


__all__ = ["lqr_rollout", "nlp_functions"]
