"""The linear MPC in C: the condensed QP and a dense ADMM written for its structure.

Per sample the C step does what :meth:`MPCController._step` does, in two parts:

- CasADi's code generation of the estimator and the QP's parameters (``flexctrl_pre.c``)::

      x = x_hat (the Kalman filter, as the LQG's),  r_j = (x_ref,j - x_op) / S_x
      z = (x - x_op) / S_x - r_0,  dv_j = (u_ref,j - u_op) / S_u,  dc_j = C r_j+1
      u_lqr = u_ref,0 - S_u K z                      (the fallback's LQR move)

- the condensed QP (:func:`~flexctrl.control.mpc.qp.condensed_qp` of the controller's scaled
  problem: the same optimum as the sparse QP, states eliminated) solved by OSQP's ADMM
  specialised to it (``mpc_dense.c``): the linear system is one ``N m`` square Cholesky factor,
  refactored only when rho adapts.  Data from numpy, every constant exact.

The C solver stops at its own tolerance, by default 1/100 of the controller's OSQP
``eps_abs`` (1/1000 without warm starts, where OSQP's cold starts end well below their
tolerance): at the same tolerance its answers would be farther from the QP's solution than
Python's OSQP (the slack penalty enters the dual test's scale).  So the harness holds the C
torques to the QP's tolerance, measured: each within twice Python's own largest distance
from the QP's solution ``u*`` (solved tightly on the recorded inputs, ``exact.csv``), and
no farther from ``u*`` than 1.1 times Python.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np

from flexctrl.control.cexport.c_code import c_array, c_double, generate, template
from flexctrl.control.cexport.library import Export, Plan, export_folder, write_library
from flexctrl.control.mpc.qp import condensed_qp
from flexctrl.errors import SpecError

#: The tolerance of the tight solve giving the QP's solution ``u*`` for the harness.
EXACT_EPS = 1e-10


def export_mpc(ctrl, out, replay=None, qp_eps: float | None = None) -> Export:
    """Write the linear MPC ``ctrl`` as a C library into ``out`` (:meth:`Controller.export_c`).

    Parameters
    ----------
    ctrl : MPCController
        Without move blocking, minimum-time arrival or a constraint stride.
    out : str or path-like
        The folder.
    replay : Replay, optional
        Its recorded steps; with them ``exact.csv`` (the QP's solutions) too.
    qp_eps : float, optional
        The C solver's absolute and relative tolerance; default 1/100 of ``osqp.eps_abs``
        (1/1000 with ``warm_start = "none"``).

    Returns
    -------
    Export
    """
    if qp_eps is not None and not (np.isfinite(qp_eps) and qp_eps > 0):
        raise SpecError(f"value {qp_eps!r} is not allowed; allowed: a tolerance > 0", key="qp_eps")
    folder = export_folder(out)
    qp = condensed_data(ctrl)
    plan = plan_mpc(ctrl, folder, qp, qp_eps)
    if replay is not None:
        u_star = exact_torques(ctrl, qp, replay)
        _write_exact(folder / "exact.csv", u_star)
        distance = np.max(np.abs(replay.u - u_star), axis=0)
        plan.check_abs = 2.0 * distance
        plan.notes["python_distance_from_qp_solution_Nm"] = distance.tolist()
    return write_library(folder, ctrl, plan, replay)


def _unsupported(ctrl) -> str | None:
    s = ctrl.settings
    if s.blocks:
        return "move blocking ('blocks')"
    if s.arrival.enabled:
        return "minimum-time arrival ('arrival')"
    if s.formulation == "condensed" and s.constraint_stride != 1:
        return "soft rows on every n-th stage ('constraint_stride')"
    return None


def condensed_data(ctrl) -> dict:
    """The condensed QP of ``ctrl``'s problem in the blocks the C solver uses.

    Raises
    ------
    SpecError
        When the QP has a part the solver does not handle (named).
    """
    what = _unsupported(ctrl)
    if what is not None:
        raise SpecError(
            f"the linear MPC's {what} has no C export; allowed: every move free, soft rows on "
            "every stage",
            key="kind",
        )
    pb = ctrl.problem
    qp = condensed_qp(pb)
    nv, nw = qp.n_moves, qp.H.shape[0]
    ns = nw - nv
    H, A = qp.H.toarray(), qp.A.toarray()
    G = A[:ns, :nv]
    checks = {
        "soft rows [G -I; G I] on the moves and slacks": np.array_equal(A[ns:, :nv], G)
        and np.array_equal(A[:ns, nv:], -np.eye(ns))
        and np.array_equal(A[ns:, nv:], np.eye(ns)),
        "a slack cost l1 s + l2/2 s's apart from the moves": not np.any(H[:nv, nv:])
        and np.array_equal(H[nv:, nv:], pb.l2 * np.eye(ns))
        and not np.any(qp.g0[:nv])
        and np.all(qp.g0[nv:] == pb.l1),
        "bounds moving with z alike on both soft blocks": qp.Lz is None
        or np.array_equal(qp.Lz[:ns], qp.Lz[ns:]),
        "moves first, stage-major": np.array_equal(qp.moves.ravel(), np.arange(nv)),
    }
    broken = [k for k, ok in checks.items() if not ok]
    if broken:
        raise SpecError(
            f"the linear MPC's QP has no C export: it lacks {'; '.join(broken)}; allowed: the "
            "condensed QP with torque bounds and one block of soft rows",
            key="kind",
        )
    CP = np.zeros((0, pb.n)) if qp.Lz is None else -qp.Lz[:ns]
    return {
        "qp": qp, "nv": nv, "ns": ns, "H": H[:nv, :nv], "G": G, "GtG": G.T @ G,
        "F": np.asarray(qp.Gz)[:nv], "CP": CP, "c_hi": qp.uba0[:ns], "c_lo": qp.lba0[ns:],
        "v_lo": qp.lbx[:nv], "v_hi": qp.ubx[:nv], "shift_w": qp.shift_w,
        "shift_y": np.r_[qp.shift_a, 2 * ns + qp.shift_w].astype(int),
    }  # fmt: skip


def pre_functions(ctrl):
    """``(pre_start, pre)``: ``(y, u_prev, X, U)`` and ``(xi, y, u_prev, X, U) -> (xi, p, u_lqr)``.

    ``X`` is ``n x (N+1)`` (column ``j`` the reference row ``k + j``, so a row-major C array
    of rows), ``U`` is ``m x (N+1)``; ``p = [z, dv, dc]`` stage-major.
    """
    import casadi as ca

    pb, obs = ctrl.problem, ctrl.observer
    n, m, N = pb.n, pb.m, pb.horizon
    y, u_prev = ca.MX.sym("y", ctrl.sensors.n_y), ca.MX.sym("u_prev", m)
    X, U = ca.MX.sym("X", n, N + 1), ca.MX.sym("U", m, N + 1)
    x_op, Sx, Su, u_op = (ca.DM(v) for v in (ctrl.op.x, pb.Sx, pb.Su, ctrl.op.u))

    def parameters(x):
        r = [(X[:, j] - x_op) / Sx for j in range(N + 1)]
        z = (x - x_op) / Sx - r[0]
        dv = [(U[:, j] - u_op) / Su for j in range(N)]
        dc = [ca.mtimes(ca.DM(pb.C), r[j + 1]) for j in range(N)] if pb.ns else []
        return ca.vertcat(z, *dv, *dc), U[:, 0] + Su * (-ca.mtimes(ca.DM(pb.K), z))

    xi_start, x_start = obs.symbolic_start(y, u_prev)
    xi = ca.MX.sym("xi", xi_start.shape[0])
    xi_next, x = obs.symbolic(xi, y, u_prev)
    outs = ["xi_next", "p", "u_lqr"]
    start = ca.Function(
        "flexctrl_pre_start", [y, u_prev, X, U], [xi_start, *parameters(x_start)],
        ["y", "u_prev", "X", "U"], outs,
    )  # fmt: skip
    step = ca.Function(
        "flexctrl_pre", [xi, y, u_prev, X, U], [xi_next, *parameters(x)],
        ["xi", "y", "u_prev", "X", "U"], outs,
    )  # fmt: skip
    return start, step


def _solver_defines(ctrl, qp_eps: float | None) -> dict[str, str]:
    o, s = ctrl.settings.osqp, ctrl.settings
    check = int(o.check_termination or 5)
    adapt = (o.adaptive_rho_interval or 4 * check) if o.adaptive_rho else 0
    # a cold-started OSQP runs on to well below its tolerance, so the C solver must go further
    tighter = 1e-3 if s.warm_start == "none" else 1e-2
    eps_abs = o.eps_abs * tighter if qp_eps is None else float(qp_eps)
    eps_rel = o.eps_rel * tighter if qp_eps is None else float(qp_eps)
    return {
        "FLEXCTRL_RHO0": c_double(o.rho),
        "FLEXCTRL_SIGMA": c_double(o.sigma),
        "FLEXCTRL_ALPHA": c_double(o.alpha),
        "FLEXCTRL_EPS_ABS": c_double(eps_abs),
        "FLEXCTRL_EPS_REL": c_double(eps_rel),
        "FLEXCTRL_MAX_ITER": str(int(o.max_iter)),
        "FLEXCTRL_CHECK_EVERY": str(check),
        "FLEXCTRL_ADAPT_INTERVAL": str(int(adapt)),
        "FLEXCTRL_WARM": str({"none": 0, "previous": 1, "shift": 2}[s.warm_start]),
        "FLEXCTRL_FALLBACK_SHIFT": "1" if s.fallback == "shift" else "0",
        "FLEXCTRL_FALLBACK_HOLD": "1" if s.fallback == "hold" else "0",
    }


def plan_mpc(ctrl, out: Path, d: dict, qp_eps: float | None) -> Plan:
    """Write the MPC's C sources into ``out``; the plan for :func:`write_library`."""
    pb = ctrl.problem
    functions = pre_functions(ctrl)
    sizes = generate(list(functions), out, "flexctrl_pre")
    (out / "mpc_dense.c").write_text(template("mpc_dense.c"))
    nv, ns, n_xi = d["nv"], d["ns"], int(functions[1].size1_in(0))
    solver = _solver_defines(ctrl, qp_eps)
    defines = {
        "FLEXCTRL_N_XI": str(n_xi),
        "FLEXCTRL_N_P": str(pb.n + pb.horizon * pb.m + ns),
        "FLEXCTRL_HORIZON": str(pb.horizon),
        "FLEXCTRL_QP_NV": str(nv),
        "FLEXCTRL_QP_NS": str(ns),
        "FLEXCTRL_L1": c_double(pb.l1),
        "FLEXCTRL_L2": c_double(pb.l2),
        **solver,
        **{f"FLEXCTRL_PRE_SZ_{k.upper()}": str(v) for k, v in sizes.items()},
    }
    names = ["H", "G", "GtG", "F", "CP", "c_hi", "c_lo", "v_lo", "v_hi"]
    data = "\n/* the condensed QP (mpc_dense.c) */\n" + "".join(
        c_array(f"flexctrl_qp_{k}", d[k]) for k in names
    )
    data += c_array("flexctrl_qp_Su", pb.Su)
    data += c_array("flexctrl_qp_shift_w", d["shift_w"], "int")
    data += c_array("flexctrl_qp_shift_y", d["shift_y"], "int")
    declarations = "".join(f"extern const double flexctrl_qp_{k}[];\n" for k in [*names, "Su"])
    declarations += "extern const int flexctrl_qp_shift_w[], flexctrl_qp_shift_y[];\n"
    eps = solver["FLEXCTRL_EPS_ABS"]
    return Plan(
        route="mpc_dense",
        sources=["flexctrl_pre.c", "mpc_dense.c"],
        members=template("mpc_dense_members.h").format(nw=nv + ns + 1, mr=3 * ns + nv + 1, nv=nv),
        defines=defines,
        law=(
            "Law: the linear MPC; its condensed QP (moves and slacks, states eliminated) solved\n"
            f" * by a dense ADMM (OSQP's iteration, adaptive rho, eps {eps}) in mpc_dense.c; the\n"
            " * Kalman filter and the QP's parameters are CasADi-generated (flexctrl_pre.c)."
        ),
        ref_window=pb.horizon + 1,
        check_rel=0.0,
        check_doc="each torque within twice Python's largest distance from the QP's solution "
        "u* (per joint), and C no farther from u* than 1.1 x Python",
        data=data,
        declarations=declarations,
        notes={"qp_moves": nv, "qp_slacks": ns, "qp_eps": float(eps)},
    )


def exact_torques(ctrl, d: dict, replay) -> np.ndarray:
    """``u*`` per recorded sample: the QP on the recorded inputs solved to :data:`EXACT_EPS`.

    The state estimate and the reference shifts are the controller's own (a copy of its
    estimator fed the recorded measurements and torques); the QP is the condensed one, solved
    by OSQP with polishing (an active-set refinement), independent of the C solver.

    Raises
    ------
    SpecError
        When the tight solve fails on a sample (then ``u*`` is not a solution).
    """
    import osqp
    import scipy.sparse as sp

    qp, pb = d["qp"], ctrl.problem
    nw = qp.H.shape[0]
    A = sp.vstack([qp.A, sp.eye(nw, format="csc")], format="csc")
    solver = osqp.OSQP()
    g, lba, uba, lbx, ubx = qp.vectors(np.zeros(pb.n))
    solver.setup(
        sp.triu(qp.H, format="csc"), g, A, np.r_[lba, lbx], np.r_[uba, ubx], verbose=False,
        eps_abs=EXACT_EPS, eps_rel=EXACT_EPS, max_iter=200000, polishing=True, scaling=10,
    )  # fmt: skip
    observer = copy.copy(ctrl.observer)
    observer.reset()
    out = np.empty_like(replay.u)
    for k in range(replay.samples):
        x = observer.estimate(replay.y[k], replay.u_prev[k])
        r, u_ref, dv, dc = ctrl.reference_shifts(float(replay.t[k]))
        z = (x - ctrl.op.x) / pb.Sx - r[0]
        g, lba, uba, lbx, ubx = qp.vectors(z, dv, dc)
        solver.update(q=g, l=np.r_[lba, lbx], u=np.r_[uba, ubx])
        res = solver.solve(raise_error=False)
        if res.info.status_val != 1:
            raise SpecError(
                f"the QP of sample {k} (t = {replay.t[k]:g} s) was not solved to {EXACT_EPS:g} "
                f"({res.info.status}); the harness has no solution to compare with",
                key="replay",
            )
        out[k] = u_ref[0] + res.x[qp.first_move] * pb.Su
    return np.clip(out, -ctrl.limits, ctrl.limits)


def _write_exact(path: Path, u_star: np.ndarray) -> None:
    with open(path, "w") as f:
        f.write("k," + ",".join(f"u{i + 1}" for i in range(u_star.shape[1])) + "\n")
        for k, row in enumerate(u_star):
            f.write(f"{k}," + ",".join(repr(float(v)) for v in row) + "\n")


__all__ = ["export_mpc", "condensed_data", "pre_functions", "plan_mpc", "exact_torques"]
