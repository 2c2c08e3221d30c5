"""Move blocking and thinned soft constraints of the condensed MPC, against a closed form."""

from __future__ import annotations

import numpy as np
import pytest

from flexctrl import linear as L
from flexctrl.control import design
from flexctrl.control.lqr import weight_matrices
from flexctrl.errors import SpecError
from flexctrl.scenes.model_files import load_model
from flexctrl.spec.controller_settings import MPCSettings, OSQPSettings

TARGET = np.radians([30.0, 0.0, 0.0])
TIGHT = OSQPSettings(eps_abs=1e-10, eps_rel=1e-10, max_iter=50000, polishing=True)
BLOCKS = (1, 1, 2, 4, 4)


@pytest.fixture(scope="module")
def arm():
    return load_model("models/subedi3link.toml", fidelity="amm:1", gravity=[0.0, 0.0])


@pytest.fixture(scope="module")
def op(arm):
    return L.equilibrium(arm, TARGET)


def blocked_closed_form(Ad, Bd, Q, R, P, blocks, dx0):
    """Minimise the horizon cost over held block moves: the normal equations in the block moves."""
    n, m = Bd.shape
    N = sum(blocks)
    owner = np.repeat(
        np.arange(len(blocks)), blocks
    )  # the block of every stage, built here, not by the code
    T = np.kron(np.eye(len(blocks))[owner], np.eye(m))
    Phi = np.vstack([np.linalg.matrix_power(Ad, k + 1) for k in range(N)])
    Gam = np.zeros((N * n, N * m))
    for k in range(N):
        for j in range(k + 1):
            Gam[k * n : (k + 1) * n, j * m : (j + 1) * m] = np.linalg.matrix_power(Ad, k - j) @ Bd
    W = np.kron(np.eye(N), Q)
    W[-n:, -n:] = P
    G = Gam @ T
    H = G.T @ W @ G + T.T @ np.kron(np.eye(N), R) @ T
    b = np.linalg.solve(H, -G.T @ W @ Phi @ dx0)
    return (T @ b).reshape(N, m)


def test_blocked_unconstrained_plan_is_the_closed_form_and_held_over_its_blocks(arm, op):
    settings = MPCSettings(
        horizon=sum(BLOCKS),
        blocks=BLOCKS,
        soft="none",
        formulation="condensed",
        osqp=TIGHT,
        scaling="none",
    )
    ctrl = design(arm, op, settings)
    ctrl.reset()
    dx = np.zeros(arm.n_x)
    dx[:3] = np.radians([0.2, -0.1, 0.15])
    ctrl.step(0.0, op.x + dx)
    plan = ctrl.plan() - op.u
    Q, R = weight_matrices(arm, settings.weights)
    expected = blocked_closed_form(ctrl.plant.Ad, ctrl.plant.Bd, Q, R, ctrl.problem.P, BLOCKS, dx)
    np.testing.assert_allclose(plan, expected, rtol=1e-5, atol=1e-6 * np.max(np.abs(expected)))
    start = 0
    for length in BLOCKS:  # one move per block
        np.testing.assert_array_equal(
            plan[start : start + length], np.repeat(plan[start : start + 1], length, axis=0)
        )
        start += length


def test_blocking_matrix_holds_each_block_move():
    from flexctrl.control.mpc.qp import blocking_matrix

    T = blocking_matrix((1, 2), 2)
    np.testing.assert_array_equal(
        T @ np.array([1.0, 2.0, 3.0, 4.0]), [1.0, 2.0, 3.0, 4.0, 3.0, 4.0]
    )


def test_blocks_of_one_are_the_unblocked_problem(arm, op):
    dx = np.zeros(arm.n_x)
    dx[:3] = np.radians([0.4, 0.1, -0.2])
    plans = []
    for blocks in ((), (1,) * 12):
        ctrl = design(
            arm, op, MPCSettings(horizon=12, blocks=blocks, formulation="condensed", osqp=TIGHT)
        )
        ctrl.reset()
        ctrl.step(0.0, op.x + dx)
        plans.append(ctrl.plan())
    np.testing.assert_allclose(plans[0], plans[1], rtol=0, atol=1e-7 * np.max(np.abs(plans[0])))


def test_thinned_soft_rows_bound_the_checked_states_by_limit_plus_slack(arm, op):
    limit = 1e-3  # m: active on a 10 degree correction (the plan needs slack: the limit is soft)
    dx = np.zeros(arm.n_x)
    dx[0] = np.radians(10.0)
    stages = [3, 7, 11, 15, 19]
    ctrl = design(
        arm,
        op,
        MPCSettings(
            horizon=20,
            blocks=(1, 1, 2, 4, 4, 8),
            soft="deflection",
            deflection_limit=limit,
            constraint_stride=4,
            formulation="condensed",
            osqp=TIGHT,
            scaling="none",
        ),
    )
    assert ctrl.qp.soft_steps.tolist() == stages
    ctrl.reset()
    ctrl.step(0.0, op.x + dx)
    pb = ctrl.problem
    slack = ctrl.last.w[ctrl.qp.slack].reshape(len(stages), pb.ns)
    assert np.max(slack) * pb.h > 1e-5  # the constraint is active
    # the predicted deflections at the checked stages, recomputed from the plan with the model
    z = dx / pb.Sx
    v = (ctrl.plan() - op.u) / pb.Su
    row = 0
    for k in range(20):
        z = pb.A @ z + pb.B @ v[k]
        if k in stages:
            assert np.all(np.abs(pb.C @ z) <= pb.c_hi + slack[row] + 1e-6)
            row += 1


@pytest.mark.parametrize(
    "kwargs, key",
    [
        ({"horizon": 10, "blocks": (2, 2, 2), "formulation": "condensed"}, "blocks"),
        ({"horizon": 6, "blocks": (2, 2, 2), "formulation": "sparse"}, "formulation"),
        ({"horizon": 6, "blocks": (2, 0, 4), "formulation": "condensed"}, "blocks"),
        ({"horizon": 6, "constraint_stride": 2, "formulation": "sparse"}, "formulation"),
        ({"horizon": 6, "constraint_stride": 7, "formulation": "condensed"}, "constraint_stride"),
    ],
)
def test_bad_blocking_settings_name_the_key(kwargs, key):
    with pytest.raises(SpecError, match=f"key '{key}'"):
        MPCSettings(**kwargs)


def test_a_held_block_respects_the_tightest_bound_of_the_stages_it_covers(arm, op):
    ctrl = design(
        arm, op, MPCSettings(horizon=6, blocks=(1, 2, 3), soft="none", formulation="condensed")
    )
    qp = ctrl.qp
    dv = np.zeros((6, arm.n_u))
    dv[:, 0] = [0.0, 0.5, 0.0, 0.0, 0.0, 0.9]
    _g, _lba, _uba, lbx, ubx = qp.vectors(np.zeros(arm.n_x), dv)
    blocks = qp.moves[[0, 1, 3], 0]
    lo, hi = ctrl.problem.v_lo[0], ctrl.problem.v_hi[0]
    np.testing.assert_allclose(ubx[blocks], [hi - 0.0, hi - 0.5, hi - 0.9])
    np.testing.assert_allclose(lbx[blocks], [lo - 0.0, lo - 0.0, lo - 0.0])


def test_the_blocked_mpcs_linear_law_is_its_own_unconstrained_first_move(arm, op):
    """With move blocking the first move is not LQR's; the linear verdict must use the MPC's own."""
    ctrl = design(
        arm,
        op,
        MPCSettings(
            horizon=sum(BLOCKS), blocks=BLOCKS, soft="none", formulation="condensed", osqp=TIGHT
        ),
    )
    K = ctrl.unconstrained_gain()
    assert np.max(np.abs(K - ctrl.K)) > 1e-3 * np.max(np.abs(ctrl.K))
    dx = np.zeros(arm.n_x)
    dx[:3] = np.radians([0.05, -0.02, 0.03])
    ctrl.reset()
    u = ctrl.step(0.0, op.x + dx)
    np.testing.assert_allclose(u - op.u, -K @ dx, rtol=1e-5, atol=1e-6 * np.max(np.abs(K @ dx)))
