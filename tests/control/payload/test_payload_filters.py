"""The payload-aware controllers' two filter banks: the rest filter's time-varying Kalman gain
against the steady-state filter DARE, the identification bank against the control bank, and
what the rest filter buys with sensor noise on (a nonlinear run)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from support import scene_arm

import flexctrl as fc
from flexctrl.control.estimator import kalman_gain

POSE = np.radians([30.0, 0.0, 90.0])
START = np.radians([0.0, 0.0, 90.0])


arm = scene_arm


def settings(**payload):
    """lqr_payload.toml on a 1 kg grid (the tests' budget) with ``payload`` keys changed."""
    s = fc.load_controller("lqr_payload")
    return dataclasses.replace(s, payload=dataclasses.replace(s.payload, grid_step=1.0, **payload))


def designed(s):
    model = arm(2.0)
    c = fc.design(model, fc.equilibrium(model, POSE), s)
    c.reset()
    return c


@pytest.fixture(scope="module")
def ctrl():
    return designed(settings())


def test_at_rest_the_gains_become_the_rest_filters_steady_state(ctrl):
    """The Riccati recursion the bank runs at rest converges to the filter DARE's solution
    (solved by doubling, a different algorithm) with the rest noise levels."""
    bank, grid = ctrl.bank, ctrl.grid
    bank.reset()
    bank.update(grid.y_op[0], grid.u_op[0])
    bank.rest(True)
    for _ in range(4000):
        bank.update(grid.y_op[0], grid.u_op[0])
    for i, design in enumerate(grid.designs):
        rest = design.rest_observer
        M, _ = kalman_gain(rest.A, rest.C, rest.W, rest.R)
        scale = np.max(np.abs(M), axis=0)
        assert np.max(np.abs(bank.M[i] - M) / scale) < 1e-4
        assert np.max(np.abs(M - grid.M[i]) / scale) > 0.1  # the rest filter is another one


def test_the_first_rest_sample_corrects_with_the_moving_gain_then_slows(ctrl):
    bank, grid = ctrl.bank, ctrl.grid
    bank.reset()
    bank.update(grid.y_op[0], grid.u_op[0])
    bank.rest(True)
    assert np.array_equal(bank.M, grid.M)
    previous = np.abs(grid.M[:, :3, :3]).max()
    for _ in range(50):
        bank.update(grid.y_op[0], grid.u_op[0])
        now = np.abs(bank.M[:, :3, :3]).max()
        assert now <= previous * (1 + 1e-9)  # the joint gains only fall while resting
        previous = now
    assert previous < 0.5 * np.abs(grid.M[:, :3, :3]).max()
    bank.rest(False)
    assert np.array_equal(bank.M, grid.M)


def test_the_verdict_is_the_law_a_run_ends_with_and_the_certificate_holds_both(ctrl):
    for i, design in enumerate(ctrl.grid.designs):
        ctrl.index = i
        E, F = ctrl.linear_law(POSE)[:2]
        rest = design.rest_observer
        np.testing.assert_array_equal(F, rest.M)
        np.testing.assert_allclose(E, (np.eye(len(rest.A)) - rest.M @ rest.C) @ rest.A)
    ctrl.index = 0
    for row in ctrl.certificate:
        assert row["worst"] == max(row["radius"] + row["radius_moving"])
        assert row["radius"] != row["radius_moving"]


def run(c, plant_kg: float, noise: bool):
    move = fc.Move(start=START, target=POSE, time=1.5)
    return fc.closed_loop(
        arm(2.0),
        c,
        move,
        4.0,
        plant=arm(plant_kg),
        noise=1 if noise else None,
        on_divergence="record",
    )


def test_identification_filters_like_the_control_ones_change_nothing():
    """A second bank with the [estimator] levels scores the payloads exactly as the first."""
    s = settings(rest_torque_noise=None, rest_modal_force_noise=None)
    apart = dataclasses.replace(
        s,
        payload=dataclasses.replace(
            s.payload,
            identify_torque_noise=s.estimator.torque_noise,
            identify_modal_force_noise=s.estimator.modal_force_noise,
        ),
    )
    alone = dataclasses.replace(
        s,
        payload=dataclasses.replace(
            s.payload, identify_torque_noise=None, identify_modal_force_noise=None
        ),
    )
    one, two = (run(designed(x), 3.0, noise=False) for x in (alone, apart))
    assert two.controller.bank.dx_identify is not None and one.controller.bank.dx_identify is None
    np.testing.assert_array_equal(one.payload_estimate["mean"], two.payload_estimate["mean"])
    np.testing.assert_array_equal(one.trajectory.inputs, two.trajectory.inputs)
    assert abs(one.payload_estimate["mean"][-1] - 3.0) < 0.2  # it identified


def test_with_sensor_noise_the_rest_filter_holds_the_tip_closer():
    """Noise on, 3 kg plant: the rest filter averages the encoder noise the moving filter
    passes to the joints (the residual window is 2.5-4 s, the move ends at 1.5 s)."""
    plain = run(designed(settings(rest_torque_noise=None, rest_modal_force_noise=None)), 3.0, True)
    rest = run(designed(settings()), 3.0, True)
    assert plain.metrics["stable"] == 1 and rest.metrics["stable"] == 1
    assert rest.metrics["tip_residual_rms"] < 0.5 * plain.metrics["tip_residual_rms"]
    assert rest.metrics["payload_estimate_error"] < 0.2


@pytest.mark.parametrize("delay", [0.0, 0.2])
def test_the_filters_rest_only_once_the_reference_has_stopped_for_the_delay(delay):
    s = settings(rest_delay=delay)
    model = arm(2.0)
    c = fc.design(model, fc.equilibrium(model, POSE), s)
    c.set_reference(fc.Move(start=START, target=POSE, time=0.5))
    c.reset()
    y = c.sensors.evaluate(c.op.x, c.op.u)
    resting = []
    for k in range(100):
        t = k * c.sample_time
        c.step(t, y)
        resting.append((t, c.bank.resting))
    stop = 0.5
    assert not any(r for t, r in resting if 0.0 < t < stop)
    assert all(r for t, r in resting if t >= stop + delay + c.sample_time)


def test_at_rest_encoder_noise_leaves_no_standing_joint_offset(ctrl):
    """The arm held at the target, zero torque, noisy encoders and strain gauges, the rest
    filter on: the joint estimates average the noise about the truth.  Velocity-product
    torques from noisy encoder differences would bias them by several thousandths of a degree
    (0.007 deg here); the bank applies them only while a joint moves."""
    bank, grid = ctrl.bank, ctrl.bank.grid
    bank.reset()
    i = grid.index_at_or_below(2.0)
    sigma = np.full(grid.y_op[i].shape, 1e-4)  # 1/m root curvature
    sigma[bank.joints] = np.radians(0.005)
    rng = np.random.default_rng(3)
    joints = []
    for k in range(int(4.0 / ctrl.sample_time)):
        bank.rest(k >= 10)
        bank.update(grid.y_op[i] + sigma * rng.standard_normal(sigma.shape), grid.u_op[i])
        joints.append(bank.dx[i][: len(bank.joints)].copy())
    last_second = np.degrees(np.array(joints[-int(1.0 / ctrl.sample_time) :]))
    assert np.max(np.abs(last_second.mean(axis=0))) < 0.002
    ctrl.reset()
