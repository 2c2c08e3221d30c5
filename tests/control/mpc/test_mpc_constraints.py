"""Bounds of one's own on the linear MPC: the QP against an independent construction solved by
its KKT system, soft bounds as exact penalties, a joint-rate bound in the closed loop, and the
bounds named by signal in Python and files."""

from __future__ import annotations

import dataclasses
import math

import control
import numpy as np
import pytest
import scipy.linalg

import flexctrl as fc
from flexctrl.errors import SpecError
from flexctrl.spec.controller_reader import load_controller
from flexctrl.spec.controller_settings import MPCSettings, OSQPSettings, SensorSettings
from flexctrl.spec.mpc_constraints import Bound

TIGHT = OSQPSettings(eps_abs=1e-6, eps_rel=1e-6, polishing=True, max_iter=200000)
Q1, R1 = np.diag([400.0, 1e4, 1.0, 1.0]), np.array([[0.05]])


def _independent_qp(model, op, Ts, N, x0, u_prev, dq_max, du_max, q_min):
    """The MPC's problem built here: condensed in the torques, every bound a row of ``G w <= h``.

    Prediction by python-control's ZOH of ``fc.linearize``; terminal cost scipy's DARE.
    """
    sysd = control.sample_system(fc.linearize(model, op), Ts, method="zoh")
    A, B = np.asarray(sysd.A), np.asarray(sysd.B)
    P = scipy.linalg.solve_discrete_are(A, B, Q1, R1)
    n, m = A.shape[0], B.shape[1]
    Phi = np.vstack([np.linalg.matrix_power(A, k + 1) for k in range(N)])
    Gam = np.zeros((N * n, N * m))
    for k in range(N):
        for j in range(k + 1):
            Gam[k * n : (k + 1) * n, j * m : (j + 1) * m] = np.linalg.matrix_power(A, k - j) @ B
    Qbar = scipy.linalg.block_diag(*([Q1] * (N - 1) + [P]))
    H = Gam.T @ Qbar @ Gam + np.kron(np.eye(N), R1)
    dx0 = x0 - op.x
    f = Gam.T @ Qbar @ Phi @ dx0
    # rows: dq1 <= dq_max and >= -dq_max on x_1..x_N; q1 >= q_min; |u_k - u_k-1| <= Ts du_max;
    # |u| <= limit
    Sq, Sdq = np.zeros((N, N * n)), np.zeros((N, N * n))
    for k in range(N):
        Sq[k, k * n], Sdq[k, k * n + 2] = 1.0, 1.0
    D = np.eye(N) - np.eye(N, k=-1)
    d0 = np.r_[op.u[0] - u_prev[0], np.zeros(N - 1)]  # u_k - u_k-1 = D du + d0
    limit = model.spec.joints[0].torque_limit
    G = np.vstack([Sdq @ Gam, -Sdq @ Gam, -Sq @ Gam, D, -D, np.eye(N), -np.eye(N)])
    h = np.r_[
        np.full(N, dq_max) - op.x[2] - Sdq @ Phi @ dx0,
        np.full(N, dq_max) + op.x[2] + Sdq @ Phi @ dx0,
        -(q_min - op.x[0] - Sq @ Phi @ dx0),
        np.full(N, Ts * du_max) - d0,
        np.full(N, Ts * du_max) + d0,
        np.full(N, limit - op.u[0]),
        np.full(N, limit + op.u[0]),
    ]
    return H, f, G, h


def _kkt(H, f, G, h, active):
    """The minimiser with the rows ``active`` held as equalities, and their multipliers."""
    Ga = G[active]
    K = np.block([[H, Ga.T], [Ga, np.zeros((Ga.shape[0],) * 2)]])
    sol = np.linalg.solve(K, np.r_[-f, h[active]])
    return sol[: H.shape[0]], sol[H.shape[0] :]


def _plan(model, op, bounds, formulation, backend, x0, u_prev):
    """The torque deviations (N m) the MPC plans from ``x0`` with ``u_prev`` held before."""
    settings = MPCSettings(
        sample_time=0.02,
        horizon=12,
        soft="none",
        Q=Q1,
        R=R1,
        constraints=bounds,
        formulation=formulation,
        backend=backend,
        osqp=TIGHT,
    )
    ctrl = fc.design(model, op, settings)
    ctrl.reset()
    ctrl.u_previous = u_prev  # the torque held in the sample that just ended, N m
    sol = ctrl.solve(x0)
    assert sol.ok, sol.status
    return sol.w[ctrl.qp.moves][:, 0] * ctrl.problem.Su[0]


def test_the_qp_solves_the_independently_built_problem(onelink):
    model, op = onelink
    Ts, N = 0.02, 12
    dq_max, du_max, q_min = 0.6, 100.0, 0.15
    bounds = (
        Bound("dq1", -dq_max, dq_max),
        Bound("du1", -du_max, du_max),
        Bound("q1", q_min, math.inf),
    )
    x0 = op.x + np.array([-0.3, 0.002, 0.5, 0.0])  # below the target, rising fast
    u_prev = op.u - 3.0
    H, f, G, h = _independent_qp(model, op, Ts, N, x0, u_prev, dq_max, du_max, q_min)
    # the active set from DAQP (an exact active-set solver), the optimum from numpy's KKT solve
    exact = _plan(model, op, bounds, "condensed", "daqp", x0, u_prev)
    active = np.flatnonzero(np.abs(G @ exact - h) <= 1e-9 * (1.0 + np.abs(h)))
    # joint-rate, torque-rate and torque-limit rows bind: the test is not unconstrained
    assert {0, 3, 5} <= set(active // N)
    w, lam = _kkt(H, f, G, h, active)
    # the KKT point is the optimum: feasible, and no active row pulls the wrong way
    assert np.all(G @ w <= h + 1e-9 * (1.0 + np.abs(h)))
    assert np.all(lam >= -1e-9 * np.max(np.abs(lam)))
    scale = np.max(np.abs(w))
    np.testing.assert_allclose(exact, w, rtol=0, atol=1e-8 * scale)
    for formulation in ("sparse", "condensed"):  # OSQP to eps 1e-6, polished
        plan = _plan(model, op, bounds, formulation, "osqp", x0, u_prev)
        np.testing.assert_allclose(plan, w, rtol=0, atol=1e-4 * scale, err_msg=formulation)


def test_a_soft_bound_with_an_exact_penalty_is_the_hard_one_and_gives_way_when_it_must(onelink):
    model, op = onelink
    Ts = 0.02
    x0 = op.x + np.array([-0.3, 0.0, -0.4, 0.0])
    plans = {}
    for soft in (False, True):
        settings = MPCSettings(
            sample_time=Ts,
            horizon=12,
            soft="none",
            constraints=(Bound("dq1", -0.6, 0.6, soft=soft),),
            formulation="condensed",
            backend="daqp",
        )
        ctrl = fc.design(model, op, settings)
        ctrl.reset()
        plans[soft] = ctrl.solve(x0).w[ctrl.qp.moves][:, 0]
    np.testing.assert_allclose(plans[True], plans[False], atol=1e-7 * np.max(np.abs(plans[False])))
    # a state already beyond a hard bound it cannot return within in one step: the hard QP fails
    # and falls back (recorded); the soft one solves and reports its violation
    x_fast = op.x + np.array([0.0, 0.0, -3.0, 0.0])
    for soft, ok in ((False, False), (True, True)):
        settings = MPCSettings(
            sample_time=Ts,
            horizon=12,
            soft="none",
            constraints=(Bound("dq1", -0.6, 0.6, soft=soft),),
            formulation="condensed",
            backend="daqp",
            fallback="lqr",
        )
        ctrl = fc.design(model, op, settings)
        ctrl.reset()
        y = ctrl.sensors.evaluate(x_fast, op.u)
        ctrl.step(0.0, y)
        assert (ctrl.stats.status.get("solved", 0) == 1) is ok
        if ok:
            assert ctrl.stats.slack_max > 1.0  # rad/s beyond the bound at the first stage
        else:
            assert ctrl.stats.fallbacks and ctrl.stats.fallbacks[0][2] == "lqr"


@pytest.fixture(scope="module")
def rigid():
    model = fc.load_model("subedi3link", payload=2.0, fidelity="rigid", gravity=[0.0, 0.0])
    return model, fc.equilibrium(model, np.radians([30.0, 0.0, 0.0]))


@pytest.mark.parametrize("formulation", ["sparse", "condensed"])
def test_a_joint_rate_bound_holds_in_the_closed_loop_where_the_free_mpc_exceeds_it(
    rigid, formulation
):
    """The quintic 30 degree move peaks at 37.5 deg/s; bounded at 25 deg/s, the arm keeps it.

    The bound holds on the QP's linear prediction; on the arm it holds to the prediction's
    one-sample error (Coriolis terms and the reference's own mismatch with the sampled linear
    model), which here is below 0.1 % of the bound.
    """
    model, op = rigid
    move = fc.Move(start=np.zeros(3), target=np.radians([30.0, 0.0, 0.0]), time=1.5)
    shipped = load_controller("mpc")  # tuned weights, OSQP to 1e-3, state measured here
    base = dataclasses.replace(
        shipped, sensors=SensorSettings(), soft="none", formulation=formulation
    )
    bound = math.radians(25.0)
    peaks = {}
    for label, constraints in (("free", ()), ("bounded", (Bound("dq1", -bound, bound),))):
        ctrl = fc.design(model, op, dataclasses.replace(base, constraints=constraints))
        result = fc.closed_loop(model, ctrl, move, duration=4.0)
        peaks[label] = float(np.max(np.abs(result.trajectory.states[:, model.n_q])))
        assert not ctrl.stats.fallbacks  # every sample solved (OSQP to its tolerance)
        assert abs(result.trajectory.states[-1, 0] - op.x[0]) < math.radians(0.01)
    assert peaks["free"] > 1.4 * bound
    assert peaks["bounded"] <= bound * (1.0 + 1e-3)


def test_bounds_read_from_files_in_their_units(tmp_path):
    path = tmp_path / "mpc.toml"
    path.write_text(
        'kind = "mpc"\n[constraints]\ndq1_deg_s = [-40.0, 40.0]\nq2_deg = [-20.0, inf]\n'
        'w1 = [-0.02, 0.02]\ntip_y = [0.2, inf]\ndu3 = [-3000, 3000]\nsoft = ["w1", "tip_y"]\n'
    )
    bounds = {b.signal: b for b in load_controller(path).constraints}
    assert bounds["dq1"].upper == pytest.approx(math.radians(40.0), rel=1e-15)
    assert (
        bounds["q2"].lower == pytest.approx(math.radians(-20.0)) and bounds["q2"].upper == math.inf
    )
    assert bounds["w1"].soft and bounds["tip_y"].soft and not bounds["dq1"].soft
    assert bounds["du3"].upper == 3000.0


@pytest.mark.parametrize(
    "text, fragments",
    [
        ("dq1 = [-1, 1]\n", ["constraints.dq1", "'dq1_deg_s'"]),
        ("speed = [-1, 1]\n", ["constraints.speed", "allowed: q<i>_deg"]),
        ("w1 = [0.02, -0.02]\n", ["constraints.w1", "lower < upper"]),
        ("w1 = 0.02\n", ["constraints.w1", "[lower, upper]"]),
        ('du1 = [-1, 1]\nsoft = ["du1"]\n', ["constraints.du1", "always hard"]),
        ('w1 = [-1, 1]\nsoft = ["w2"]\n', ["constraints.soft", "'w2'"]),
    ],
)
def test_bad_bounds_in_files_name_the_key(tmp_path, text, fragments):
    path = tmp_path / "mpc.toml"
    path.write_text('kind = "mpc"\n[constraints]\n' + text)
    with pytest.raises(SpecError) as info:
        load_controller(path)
    for fragment in fragments:
        assert fragment in str(info.value), str(info.value)


def test_bounds_the_model_lacks_are_named_at_design(onelink, rigid):
    model, op = onelink
    for signal, fragment in (("q2", "1-joint arm"), ("du3", "1-joint arm")):
        with pytest.raises(SpecError) as info:
            fc.design(model, op, MPCSettings(constraints=(Bound(signal, -1.0, 1.0),)))
        assert info.value.key == f"constraints.{signal}" and fragment in str(info.value)
    model, op = rigid
    settings = MPCSettings(soft="none", constraints=(Bound("w1", -0.01, 0.01),))
    with pytest.raises(SpecError, match="without modes"):
        fc.design(model, op, dataclasses.replace(settings, sensors=SensorSettings()))
    with pytest.raises(SpecError, match="HPIPM"):
        MPCSettings(backend="hpipm", constraints=(Bound("du1", -1.0, 1.0),))
    with pytest.raises(SpecError, match="twice"):
        MPCSettings(constraints=(Bound("q1", -1.0, 1.0), Bound("q1", 0.0, 1.0)))


def test_a_hard_bound_the_target_breaks_is_refused_at_design_and_a_soft_one_is_not(onelink):
    model, op = onelink
    q1 = float(op.x[0])
    outside = Bound("q1", q1 + 0.1, q1 + 0.2)
    with pytest.raises(SpecError) as info:
        fc.design(model, op, MPCSettings(constraints=(outside,)))
    assert info.value.key == "constraints.q1" and "could never settle" in str(info.value)
    soft = dataclasses.replace(outside, soft=True)
    assert fc.design(model, op, MPCSettings(constraints=(soft,))).settings.constraints == (soft,)
    inside = Bound("q1", q1 - 0.1, q1 + 0.1)
    fc.design(model, op, MPCSettings(constraints=(inside,)))
