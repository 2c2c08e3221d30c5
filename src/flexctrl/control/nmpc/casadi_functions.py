"""The NMPC's CasADi Functions, built once per design, and the layout of its variables.

The linearization and QP assembly, the QP solver, the cost, the bounds, the first guess's
rollout and the full NLP.

The compiled part (the horizon's linearization,
:func:`~flexctrl.control.nmpc.interval.horizon_linearization`) sees the operating point, the
scales and the model's constants as inputs, so one library serves every operating point,
reference and (frozen-modes) configuration whose model graph has the same structure; it is
found on disk by its recipe before it is built.  The QP is assembled around it in CasADi's
virtual machine, one Function of ``(z0, w)``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp

from flexctrl.control.lqr import LinearPlant
from flexctrl.control.mpc.problem import ScaledProblem
from flexctrl.control.mpc.qp import _shift_blocks
from flexctrl.control.nmpc.interval import horizon_linearization, interval_core, memoised
from flexctrl.control.nmpc.nlp import lqr_rollout, nlp_functions
from flexctrl.control.nmpc.screened_qp import hpipm_options
from flexctrl.dynamics.parametric import constants_as_parameters
from flexctrl.dynamics.parametric import try_expand as _expanded
from flexctrl.sim.compile import content_key
from flexctrl.spec.controller_settings import NMPCSettings


class Layout:
    """Index bookkeeping of ``w = [z_0, v_0, s_0, ..., z_N]``.

    Parameters
    ----------
    n, m, ns : int
        States, inputs and soft rows (slacks) per stage.
    N : int
        Shooting intervals.
    """

    def __init__(self, n: int, m: int, ns: int, N: int):
        self.n, self.m, self.ns, self.N = n, m, ns, N
        self.blk = n + m + ns
        self.nw = N * self.blk + n
        self.z = np.array(
            [k * self.blk + np.arange(n) for k in range(N)] + [N * self.blk + np.arange(n)]
        )
        self.v = np.array([k * self.blk + n + np.arange(m) for k in range(N)])
        self.s = np.array([k * self.blk + n + m + np.arange(ns) for k in range(N)]).reshape(N, ns)
        self.shift = _shift_blocks(0, self.blk, N, N * self.blk + np.arange(n))

    def split(self, w):
        """(Z (n x N+1), V (m x N), S (ns x N)) of a symbolic or numeric ``w``."""
        head = ca.reshape(w[: self.N * self.blk], self.blk, self.N)
        Z = ca.horzcat(head[: self.n, :], w[self.N * self.blk :])
        return Z, head[self.n : self.n + self.m, :], head[self.n + self.m :, :]


def build_functions(
    model,
    plant: LinearPlant,
    settings: NMPCSettings,
    pb: ScaledProblem,
    substeps: int,
    per_use: bool = False,
):
    """The CasADi Functions of the NMPC, its layout and whether the linearization is compiled.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The model predicted with.
    plant : LinearPlant
        Its linearization at the target (operating point, sample time).
    settings : NMPCSettings
        The controller's settings.
    pb : ScaledProblem
        The scales, weights and soft rows.
    substeps : int
        RK4 steps per sample.
    per_use : bool
        Lift one constant per use (:func:`constants_as_parameters`), for models whose
        constants coincide by value at some configurations (the reduced prediction's basis).

    Returns
    -------
    tuple
        ``(functions, layout, compiled)``: the Functions and arrays by name (``prepare``,
        ``qp``, ``H``, ``g0``, ``lbx0``, ``ubx0``, ``rollout``, ``linmap``, ``F``, ``params``,
        ``build`` and, for the full NLP, ``nlp``, ``lbg``, ``ubg``), the :class:`Layout` and
        whether the linearization is a compiled library.
    """
    n, m, ns, N = pb.n, pb.m, pb.ns, pb.horizon
    lay = Layout(n, m, ns, N)
    Fz = _scaled_shooting(model, plant, pb, substeps)
    fp, const = constants_as_parameters(model.functions["f"], per_use=per_use)
    params = np.concatenate([plant.op.x, plant.op.u, pb.Sx, pb.Su, const])
    P = ca.DM(params)
    linmap, compiled, compile_seconds, cache_hit, reused = _linearization(
        fp, const.size, plant, settings, lay, substeps, P, Fz
    )
    z0, w = ca.MX.sym("z0", n), ca.MX.sym("w", lay.nw)
    prepare = ca.Function(
        "nmpc_prepare",
        [z0, w],
        _assembly(linmap, lay, w, P, ca.DM(pb.C), ca.DM(pb.c_lo), ca.DM(pb.c_hi)),
        ["z0", "w"],
        ["a", "lba", "uba"],
    )
    lbx0, ubx0, H, g = _bounds_and_cost(pb, lay)
    Hs = ca.DM(ca.sparsify(ca.DM(H)))
    qp = _qp_solver(settings, lay, Hs, prepare.sparsity_out(0))
    functions = {
        "prepare": prepare,
        "lbx0": lbx0,
        "ubx0": ubx0,
        "qp": qp,
        "H": Hs,
        "g0": g,
        "Hnp": sp.csr_matrix(H),
        "rollout": lqr_rollout(_lqr_step(pb, Fz), N, n, m),
        "linmap": linmap,
        "F": Fz,
        "params": params,
        "build": {
            "compile_seconds": compile_seconds,
            "cache_hit": cache_hit,
            "n_constants": const.size,
            "reused": reused,
        },
    }
    # full NLP (also the RTI initialisation)
    if settings.mode == "full" or settings.init_iter > 0:
        functions.update(nlp_functions(settings, pb, lay, Fz, H, g))
    return functions, lay, compiled


def _scaled_shooting(model, plant: LinearPlant, pb: ScaledProblem, substeps: int):
    """``Fz(z, v) -> z_next``: the model's RK4 shooting map in scaled deviations."""
    n, m = pb.n, pb.m
    F, _ = interval_core(_expanded(model.functions["f"]), n, m, plant.dt, substeps, None)
    xop_d, uop_d, Sx_d, Su_d = (ca.DM(a) for a in (plant.op.x, plant.op.u, pb.Sx, pb.Su))
    zz_, vv_ = ca.MX.sym("z", n), ca.MX.sym("v", m)
    return ca.Function(
        "nmpc_F", [zz_, vv_], [(F(xop_d + Sx_d * zz_, uop_d + Su_d * vv_) - xop_d) / Sx_d]
    )


def _lqr_step(pb: ScaledProblem, Fz: ca.Function) -> ca.Function:
    """One sample under the saturated LQR law about the reference (the first guess's rollout)."""
    n, m = pb.n, pb.m
    zr, zref, vref = ca.MX.sym("z", n), ca.MX.sym("z_ref", n), ca.MX.sym("v_ref", m)
    vr = ca.fmin(ca.fmax(vref - ca.mtimes(ca.DM(pb.K), zr - zref), ca.DM(pb.v_lo)), ca.DM(pb.v_hi))
    return ca.Function("nmpc_lqr_step", [zr, zref, vref], [Fz(zr, vr), vr])


def _linearization(fp, nc: int, plant, settings, lay: Layout, substeps: int, P, Fz):
    """The horizon's compiled linearization, found by its recipe or built.

    A library found by its recipe is checked against the model's own RK4 at a generic point.
    """
    n, m, N = lay.n, lay.m, lay.N
    # it depends on the lifted f, the sizes and the recipe alone: built (and compiled) once per
    # worker for every configuration of one model structure
    try:
        key = content_key(
            fp.serialize(),
            n,
            m,
            nc,
            N,
            plant.dt,
            substeps,
            settings.sensitivities,
            settings.jacobian_every,
            settings.compile,
            # named only when grouped: the per-interval key (and its library) stays as it was
            *([settings.stages_per_jacobian] if settings.stages_per_jacobian > 1 else []),
        )
    except RuntimeError:  # a Function CasADi cannot serialize: built for this design alone
        key = None

    def reproduces_the_model(linmap: ca.Function) -> bool:
        # the first interval's shooting end at a generic point against the model's own RK4
        z, v = 1e-3 * np.sin(np.arange(1, n + 1)), 1e-3 * np.cos(np.arange(1, m + 1))
        ends = np.array(linmap(np.tile(z[:, None], N), np.tile(v[:, None], N), P)[0])[:, 0]
        expected = np.array(Fz(z, v)).ravel()
        return bool(np.max(np.abs(ends - expected)) <= 1e-9 * (1.0 + np.max(np.abs(expected))))

    def build():
        return horizon_linearization(
            fp,
            nc,
            n,
            m,
            N,
            plant.dt,
            substeps,
            settings,
            recipe=key,
            check=reproduces_the_model,
        )

    return memoised(key, build) if key is not None else (*build(), False)


def _bounds_and_cost(pb: ScaledProblem, lay: Layout):
    """The variables' bounds (inputs and slacks) and the QP's Hessian and gradient."""
    N, ns = lay.N, lay.ns
    lbx0, ubx0 = np.full(lay.nw, -np.inf), np.full(lay.nw, np.inf)
    for k in range(N):
        lbx0[lay.v[k]], ubx0[lay.v[k]] = pb.v_lo, pb.v_hi
        if ns:
            lbx0[lay.s[k]] = 0.0
    H = np.zeros((lay.nw, lay.nw))
    g = np.zeros(lay.nw)
    for k in range(N):
        H[np.ix_(lay.z[k], lay.z[k])] = pb.Q
        H[np.ix_(lay.v[k], lay.v[k])] = pb.R
        if ns:
            H[np.ix_(lay.s[k], lay.s[k])] = pb.l2 * np.eye(ns)
            g[lay.s[k]] = pb.l1
    H[np.ix_(lay.z[N], lay.z[N])] = pb.P
    return lbx0, ubx0, H, g


def _qp_solver(settings: NMPCSettings, lay: Layout, Hs, a_sp) -> ca.Function:
    """The RTI's QP solver through ``casadi.conic`` (``settings.qp_solver``)."""
    opts: dict = {"error_on_fail": False}
    if settings.qp_solver == "hpipm":
        opts.update(hpipm_options(lay.N, lay.n, lay.m + lay.ns, 2 * lay.ns, settings.qp_warm_start))
    elif settings.qp_solver == "qpoases":
        opts.update({"printLevel": "none", "sparse": True})
    elif settings.qp_solver == "osqp":
        opts.update(
            {
                "osqp": {
                    "verbose": False,
                    "eps_abs": 1e-5,
                    "eps_rel": 1e-5,
                    "max_iter": 4000,
                    "polishing": True,
                }
            }
        )
    return ca.conic("nmpc_qp", settings.qp_solver, {"h": Hs.sparsity(), "a": a_sp}, opts)


def _assembly(linmap: ca.Function, lay: Layout, w, p, C, c_lo, c_hi) -> list:
    """``[A, lba, uba]`` of the RTI's QP along ``w`` (MX): shooting rows, then soft rows."""
    n, m, ns, N = lay.n, lay.m, lay.ns, lay.N
    Z, V, _S = lay.split(w)
    Fk, Ak, Bk = linmap(Z[:, :N], V, p)
    rows, lba, uba = [], [], []
    for k in range(N):
        A_k = Ak[:, k * n : (k + 1) * n]
        B_k = Bk[:, k * m : (k + 1) * m]
        b_k = ca.mtimes(A_k, Z[:, k]) + ca.mtimes(B_k, V[:, k]) - Fk[:, k]
        left = k * lay.blk
        right = lay.nw - left - lay.blk - n
        rows.append(
            ca.horzcat(ca.MX(n, left), A_k, B_k, ca.MX(n, ns), -ca.MX.eye(n), ca.MX(n, right))
        )
        lba.append(b_k)
        uba.append(b_k)
        if ns:
            CA, CB = ca.mtimes(C, A_k), ca.mtimes(C, B_k)
            Cb = ca.mtimes(C, b_k)
            I_s = ca.MX.eye(ns)
            for sign, lo, hi in (
                (-1.0, -ca.inf * ca.DM.ones(ns), c_hi + Cb),
                (1.0, c_lo + Cb, ca.inf * ca.DM.ones(ns)),
            ):
                rows.append(ca.horzcat(ca.MX(ns, left), CA, CB, sign * I_s, ca.MX(ns, n + right)))
                lba.append(lo)
                uba.append(hi)
    return [ca.vertcat(*rows), ca.vertcat(*lba), ca.vertcat(*uba)]


__all__ = ["Layout", "build_functions"]
