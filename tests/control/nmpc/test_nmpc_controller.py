"""Nonlinear MPC: RTI iterates converge to the IPOPT optimum; closed loop; fallbacks."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from flexctrl import linear as L
from flexctrl.control import design
from flexctrl.control.nmpc.controller import RK4_BOUND, auto_substeps, design_nmpc
from flexctrl.dynamics.amm import build_amm
from flexctrl.spec.arm import arm_from_document
from flexctrl.spec.controller_settings import NMPCSettings

SMALL = dict(compile=False, horizon=15, sample_time=0.02, deflection_limit=0.02)


def test_rti_with_exact_sensitivities_converges_to_the_ipopt_optimum(onelink):
    model, op = onelink
    x = op.x.copy()
    x[0] -= 0.3  # far enough to saturate the torque and bend the link past the limit
    full = design(model, op, NMPCSettings(mode="full", max_iter=300, **SMALL))
    full.reset()
    nlp = full.solve(x)
    assert nlp.ok
    rti = design(model, op, NMPCSettings(sensitivities="exact", **SMALL))
    z0 = (x - op.x) / rti.problem.Sx
    w = rti.initial_guess(z0)
    for _ in range(8):  # SQP iterations at a fixed state (what RTI does across samples)
        sol = rti._rti(z0, w)
        assert sol.ok
        w = sol.w
    scale = np.max(np.abs(nlp.w))
    assert np.max(np.abs(w - nlp.w)) < 1e-3 * scale
    v = w[rti.layout.v]
    assert np.any(
        np.isclose(np.abs(v * rti.problem.Su + op.u), 15.0, rtol=1e-4)
    )  # the torque limit is active


def test_frozen_sensitivities_reach_a_feasible_point_near_the_optimum(onelink):
    model, op = onelink
    x = op.x.copy()
    x[0] -= 0.3
    full = design(model, op, NMPCSettings(mode="full", max_iter=300, **SMALL))
    nlp = full.solve(x)
    rti = design(model, op, NMPCSettings(sensitivities="frozen", **SMALL))
    z0 = (x - op.x) / rti.problem.Sx
    w = rti.initial_guess(z0)
    for _ in range(10):
        w = rti._rti(z0, w).w
    Z, V, _S = (np.array(a) for a in rti.layout.split(ca.DM(w)))
    ends = np.array(rti.functions["F"].map(rti.layout.N)(Z[:, :-1], V))
    assert np.max(np.abs(ends - Z[:, 1:])) < 1e-8 * max(
        1.0, np.max(np.abs(Z))
    )  # nonlinear shooting closed
    first = lambda ww: ww[rti.layout.v[0]]  # noqa: E731
    assert np.max(np.abs(first(w) - first(nlp.w))) < 0.05 * np.max(np.abs(nlp.w[rti.layout.v]))


def test_rti_closed_loop_reaches_the_target_within_torque_limits(onelink):
    model, op = onelink
    ctrl = design(model, op, NMPCSettings(**SMALL))
    ctrl.reset()
    F = ctrl.functions["F"]
    pb = ctrl.problem
    x = op.x.copy()
    x[0] -= 0.4
    for k in range(150):
        u = ctrl.step(k * ctrl.sample_time, x)
        assert np.all(np.abs(u) <= 15.0 + 1e-6)
        x = op.x + pb.Sx * np.array(F((x - op.x) / pb.Sx, (u - op.u) / pb.Su), dtype=float).ravel()
    assert abs(x[0] - op.x[0]) < 1e-3
    assert ctrl.stats.fallbacks == []
    assert ctrl.stats.summary()["status"] == {"solved": 150}


def test_qp_failure_falls_back_to_the_shifted_plan_then_lqr(onelink):
    model, op = onelink
    ctrl = design_nmpc(model, op, NMPCSettings(**SMALL))
    ctrl.screen = False  # always the whole QP: the one made to fail
    ctrl.reset()
    x = op.x.copy()
    x[0] -= 0.05
    ctrl.step(0.0, x)
    plan = ctrl._plan.copy()
    good = ctrl.functions["qp"]
    H, a_sp = ctrl.functions["H"], ctrl.functions["prepare"].sparsity_out(0)
    lay = ctrl.layout
    ctrl.functions["qp"] = ca.conic(
        "failing",
        "hpipm",
        {"h": H.sparsity(), "a": a_sp},
        {
            "N": lay.N,
            "nx": [lay.n] * (lay.N + 1),
            "nu": [lay.m + lay.ns] * lay.N + [0],
            "ng": [2 * lay.ns] * lay.N + [0],
            "hpipm": {"iter_max": 1},
            "error_on_fail": False,
        },
    )
    ctrl._rti_calls = None  # bound anew to the failing solver
    u = ctrl.step(0.02, x)
    np.testing.assert_allclose(u, op.u + ctrl.problem.Su * plan[1])
    assert ctrl.stats.fallbacks[-1][2] == "shift"
    for k in range(2, lay.N + 1):
        u = ctrl.step(0.02 * k, x)
    assert ctrl.stats.fallbacks[-1][2] == "lqr"
    ctrl.functions["qp"] = good
    ctrl._rti_calls = None
    ctrl.step(1.0, x)
    assert ctrl.stats.status["solved"] == 2


def test_auto_substeps_respect_the_rk4_bound(onelink):
    model, op = onelink
    ctrl = design(model, op, NMPCSettings(**SMALL))
    lam = np.max(np.abs(np.linalg.eigvals(np.asarray(ctrl.plant.sys.A))))
    h = ctrl.sample_time / ctrl.substeps
    assert lam * h <= RK4_BOUND
    assert ctrl.substeps == 1 or lam * ctrl.sample_time / (ctrl.substeps - 1) > RK4_BOUND
    assert auto_substeps(ctrl.plant) == ctrl.substeps


@pytest.mark.slow
def test_rti_on_the_three_link_arm_converges_without_fallbacks():
    # the step time is a benchmark figure (`flexctrl bench mpc`), not a timed test: this machine is
    # shared
    from flexctrl.scenes.model_files import load_model

    model = load_model("models/subedi3link.toml", fidelity="amm:2")
    op = L.equilibrium(model, np.radians([80.0, -10.0, -10.0]))
    ctrl = design(model, op, NMPCSettings(horizon=20, sample_time=0.01))
    ctrl.reset()
    F, pb = ctrl.functions["F"], ctrl.problem
    x = op.x.copy()
    x[:3] += np.radians([3.0, -3.0, 3.0])
    for k in range(100):
        u = ctrl.step(0.01 * k, x)
        x = op.x + pb.Sx * np.array(F((x - op.x) / pb.Sx, (u - op.u) / pb.Su), dtype=float).ravel()
    summary = ctrl.stats.summary()
    assert summary["steps"] == 100 and summary["fallbacks"] == 0
    assert np.max(np.abs(x[:3] - op.x[:3])) < np.radians(3.0) * 0.5


def test_compiled_linearization_is_independent_of_the_operating_point_and_the_model_constants(
    onelink,
):
    """One generated library serves every target, reference and model of the same graph structure.

    (A payload mass of 0 or of a value CasADi keeps as a shared constant, 0.5 here, changes the
    structure; a stiffer link and another payload inertia do not.)
    """
    from flexctrl.dynamics.parametric import constants_as_parameters

    model, op = onelink
    fp, const = constants_as_parameters(model.functions["f"])
    assert const.size > 0
    x, u = np.linspace(-0.3, 0.4, model.n_x), np.array([1.5])
    np.testing.assert_allclose(
        np.array(fp(x, u, const)), np.array(model.functions["f"](x, u)), rtol=1e-13, atol=1e-13
    )
    a = design(model, op, NMPCSettings(**SMALL))
    b = design(model, L.equilibrium(model, [1.1]), NMPCSettings(**SMALL))
    stiffer = build_amm(
        arm_from_document(
            {
                "name": "onelink",
                "gravity": [0.0, -9.81],
                "payload": {"mass": 0.5, "inertia": 2e-3},
                "links": [
                    {
                        "length": 1.0,
                        "mass_per_length": 1.5,
                        "EI": 600.0,
                        "inertia": 1.5 / 12,
                        "n_modes": 1,
                        "damping_ratio": 0.03,
                    }
                ],
                "joints": [{"hub_mass": 0.0, "hub_inertia": 0.05, "torque_limit": 15.0}],
            },
            "onelink.toml",
        ),
        1,
    )
    c = design(stiffer, L.equilibrium(stiffer, [0.5]), NMPCSettings(**SMALL, substeps=a.substeps))
    assert not np.allclose(a.functions["params"], b.functions["params"])
    assert a.functions["linmap"].serialize() == b.functions["linmap"].serialize()
    assert a.functions["linmap"].serialize() == c.functions["linmap"].serialize()


def test_non_finite_qp_data_and_qp_exceptions_fall_back_and_reset_the_warm_start(onelink):
    model, op = onelink
    ctrl = design(model, op, NMPCSettings(**SMALL))
    ctrl.reset()
    x = op.x.copy()
    x[0] -= 0.05
    ctrl.step(0.0, x)
    plan = ctrl._plan.copy()
    calls = ctrl._calls()  # the RTI's two calls per sample (nmpc_calls)
    linearize, solve = calls.linearize, calls.solve

    def nan_bounds(z0, w):
        a, lba, uba = linearize(z0, w)
        lba = lba.copy()
        lba[3] = np.nan
        return a, lba, uba

    calls.linearize = nan_bounds
    u = ctrl.step(0.02, x)  # would be HPIPM's "Ill-posed problem detected" assertion
    np.testing.assert_allclose(u, op.u + ctrl.problem.Su * plan[1])
    t, reason, used = ctrl.stats.fallbacks[-1]
    assert (t, used) == (0.02, "shift") and "NaN" in reason
    assert ctrl._w is None  # the next sample starts from a fresh rollout
    calls.linearize = linearize

    def raising_qp(*args):
        raise RuntimeError(
            "Error in Function::call for 'nmpc_qp' [HpipmInterface]: Ill-posed problem detected"
        )

    calls.solve = raising_qp
    u = ctrl.step(0.04, x)
    assert np.all(np.isfinite(u))
    assert (
        "QP solver error" in ctrl.stats.fallbacks[-1][1]
        and "Ill-posed" in ctrl.stats.fallbacks[-1][1]
    )
    calls.solve = solve
    ctrl.step(0.06, x)
    assert ctrl.stats.status["solved"] == 2
    assert ctrl.stats.summary()["fallbacks"] == 2


def test_three_link_step_move_that_used_to_raise_nan_settles_like_lqr():
    """Payload 0, q0 = (0, -150, -30) deg, 30 deg step of joint 1: the RTI with one Jacobian per
    sample at its start diverged and HPIPM aborted on NaN bounds; with one Jacobian per RK4 step, or
    one per
    sample at its middle node (controllers/nmpc.toml now), NMPC settles."""
    from flexctrl.scenes.run_closed_loop_scene import run_closed_loop_scene
    from flexctrl.spec.scene import load_scene

    scene = load_scene(
        "studies/scenes/move_joint1_30deg.toml",
        ["payload=0.0", "initial.q=[0.0,-150.0,-30.0]", 'target.profile="step"', "duration=4.0"],
    )
    lqr = run_closed_loop_scene(
        scene, controller="tests/data/controllers/lqr_full_state.toml", on_divergence="record"
    )
    assert lqr.summary["metrics"]["settled"] == 1
    nmpc = run_closed_loop_scene(scene, controller="controllers/nmpc.toml", on_divergence="record")
    metrics = nmpc.summary["metrics"]
    assert metrics["stable"] == 1 and metrics["settled"] == 1
    report = nmpc.summary["controller"]
    assert report["fallbacks"] == sum(
        v for k, v in report["status"].items() if k.startswith("fallback_")
    )
