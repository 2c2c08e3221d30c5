"""Minimum-time arrival of the linear MPC: against the bang-bang closed form, and on the arm."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support import DATA

import flexctrl as fc
from flexctrl.control.mpc.arrival_search import shortest_arrival
from flexctrl.control.mpc.problem import ScaledProblem
from flexctrl.control.mpc.qp import condensed_qp
from flexctrl.errors import SpecError
from flexctrl.spec.arrival import ArrivalSettings
from flexctrl.spec.controller_settings import MPCSettings


def double_integrator(
    inertia: float, torque: float, Ts: float, horizon: int, band: float
) -> ScaledProblem:
    """A rigid joint (kg m^2) under a torque limit (N m), ZOH at Ts, an arrival row on its angle."""
    A = np.array([[1.0, Ts], [0.0, 1.0]])
    B = (
        torque / inertia * np.array([[0.5 * Ts**2], [Ts]])
    )  # scaled input: v = u / torque in [-1, 1]
    eye = np.eye(2)
    return ScaledProblem(
        A=A,
        B=B,
        Q=eye,
        R=np.eye(1),
        P=eye,
        K=np.zeros((1, 2)),
        Sx=np.ones(2),
        Su=np.ones(1),
        v_lo=np.array([-1.0]),
        v_hi=np.array([1.0]),
        C=np.array([[1.0, 0.0]]),
        c_lo=np.array([-band]),
        c_hi=np.array([band]),
        h=1.0,
        l1=1e3,
        l2=1e3,
        horizon=horizon,
        n_arrival=1,
    )


@pytest.mark.parametrize("angle", [0.2, 0.5, 1.0])
@pytest.mark.parametrize("stride", [1, 4])
def test_shortest_arrival_is_the_bang_bang_time(angle, stride):
    # accelerate at full torque for half the time, brake for the other half: t* = 2 sqrt(angle I /
    # tau)
    inertia, torque, Ts = 2.0, 1.0, 0.02
    t_star = 2.0 * math.sqrt(angle * inertia / torque)
    pb = double_integrator(inertia, torque, Ts, horizon=int(1.5 * t_star / Ts) + 10, band=1e-5)
    qp = condensed_qp(pb, stride=stride)
    j = shortest_arrival(qp, np.array([-angle, 0.0]))
    steps = np.arange(pb.horizon) if qp.soft_steps is None else qp.soft_steps
    t_arrival = (steps[j] + 1) * Ts
    assert abs(t_arrival - t_star) <= stride * Ts + 1e-9, (t_arrival, t_star)
    if j > 0:  # one constrained stage earlier is infeasible (a 10 % weaker torque would be slower)
        assert (steps[j - 1] + 1) * Ts < t_star + 1e-9


def test_too_short_a_horizon_has_no_arrival():
    pb = double_integrator(2.0, 1.0, 0.02, horizon=50, band=1e-5)  # 1 s for a 2 s move
    assert shortest_arrival(condensed_qp(pb), np.array([-0.5, 0.0])) is None


def test_arrival_needs_the_condensed_form_and_a_positive_band():
    with pytest.raises(SpecError, match="formulation"):
        MPCSettings(arrival=ArrivalSettings(kind="minimum_time"), formulation="sparse")
    with pytest.raises(SpecError, match="band"):
        ArrivalSettings(kind="minimum_time", band=0.0)


def test_unknown_arrival_key_is_refused(tmp_path):
    text = (
        (DATA / "studies" / "tuning" / "start" / "mpc_time_optimal.toml")
        .read_text()
        .replace("margin =", "margn =")
    )
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(SpecError, match="margn"):
        fc.load_controller(path)


@pytest.fixture(scope="module")
def fast_runs():
    fast = fc.load_scene(DATA / "studies" / "scenes" / "fast_move_30deg.toml")
    quintic = fc.load_scene(DATA / "studies" / "scenes" / "move_joint1_30deg.toml")
    mpc = fc.run_scene(
        fast, controller=str(DATA / "controllers" / "mpc_time_optimal.toml"), plots=False
    )
    lqr = fc.run_scene(quintic, controller=str(DATA / "controllers" / "lqr.toml"), plots=False)
    return mpc, lqr


def test_time_optimal_mpc_settles_in_under_0_7_of_the_quintic_lqr(fast_runs):
    mpc, lqr = fast_runs
    assert mpc.metrics["settled"] == 1 and lqr.metrics["settled"] == 1
    assert mpc.metrics["settling_time"] <= 0.7 * lqr.metrics["settling_time"]


def test_time_optimal_mpc_keeps_the_torque_limits_and_plans_a_feasible_arrival(fast_runs):
    mpc, _ = fast_runs
    limits = np.array([200.0, 100.0, 50.0])  # N m, models/subedi3link.toml
    torques = mpc.to_pandas()[["u1", "u2", "u3"]].to_numpy()
    assert np.all(np.abs(torques) <= limits * (1 + 1e-12))
    summary = mpc.summary[
        "controller"
    ]  # (solve times are benchmark figures: docs/guide/design-a-controller.md)
    assert summary["arrival_feasible"]
    assert (
        mpc.metrics["settling_time"] + 0.1 >= summary["arrival_time_s"]
    )  # inside the band once planned


def test_release_lifts_only_the_arrival_rows_of_the_released_stages():
    pb = double_integrator(2.0, 1.0, 0.02, horizon=12, band=1e-3)
    qp = condensed_qp(pb, stride=3)  # constrained stages 2, 5, 8, 11 (0-based)
    release = np.array([True, True, False, False])
    _g, lba, uba, _lbx, _ubx = qp.vectors(np.array([-0.1, 0.0]), release=release)
    _g, lba0, uba0, _lbx, _ubx = qp.vectors(np.array([-0.1, 0.0]))
    upper, lower = (
        qp.soft_rows[:, 0],
        qp.soft_rows[:, 1],
    )  # one (arrival) row per stage: upper, lower
    assert np.all(np.isinf(uba[upper[release]])) and np.all(np.isinf(lba[lower[release]]))
    np.testing.assert_array_equal(uba[upper[~release]], uba0[upper[~release]])
    np.testing.assert_array_equal(lba[lower[~release]], lba0[lower[~release]])
    assert np.all(np.isfinite(uba0[upper])) and np.all(np.isfinite(lba0[lower]))
