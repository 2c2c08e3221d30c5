"""``fc.Plant``: the arm stepped one sample at a time, checked against ``fc.closed_loop``,
an independent integration (scipy), the model's own output functions and its limits."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.integrate

import flexctrl as fc
from flexctrl.errors import SimulationError, SpecError

DAMPED = [f"links[{i}].damping_ratio=0.005" for i in (1, 2, 3)]
TARGET = np.radians([30.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def arm():
    """The three-link arm, one mode per link, 2 kg, horizontal, 0.5 % modal damping."""
    return fc.load_model(
        "subedi3link", payload=2.0, fidelity="amm:1", gravity=[0.0, 0.0], overrides=DAMPED
    )


@pytest.fixture(scope="module")
def move():
    return fc.Move(start=np.zeros(3), target=TARGET, time=1.5)


@pytest.mark.parametrize("name", ["lqr", "mpc"])
def test_an_own_loop_ends_where_closed_loop_ends(arm, move, name):
    ctrl = fc.design(arm, fc.equilibrium(arm, TARGET), fc.load_controller(name))
    result = fc.closed_loop(arm, ctrl, move, duration=4.0)
    ctrl.set_reference(move)
    ctrl.reset()
    plant = fc.Plant.for_controller(arm, ctrl, move.start)
    assert plant.measurement_names == ctrl.measurement_names
    y = plant.output()
    for _ in range(math.ceil(4.0 / ctrl.sample_time - 1e-9)):
        y = plant.step(ctrl.step(plant.time, y))
    last = result.trajectory.states[-1]
    assert plant.time == pytest.approx(result.trajectory.time[-1], abs=1e-12)
    assert np.degrees(np.max(np.abs(plant.state[:3] - last[:3]))) < 1e-3
    # the whole run agrees, and the move happened (the check is not trivially met)
    trajectory = plant.trajectory()
    np.testing.assert_allclose(trajectory.tip, result.trajectory.tip, atol=1e-9)
    assert abs(plant.state[0] - TARGET[0]) < math.radians(0.5)


def test_one_step_converges_to_scipy_at_fourth_order_and_clips_to_the_limits(arm):
    x0 = np.zeros(arm.n_x)
    x0[arm.n_q] = 0.3  # joint 1 turning
    limits = np.array([j.torque_limit for j in arm.spec.joints])
    u = np.array([1e4, -20.0, 5.0])  # joint 1 far beyond its limit
    held = np.clip(u, -limits, limits)
    f = arm.functions["f"]
    sol = scipy.integrate.solve_ivp(
        lambda t, x: np.array(f(x, held), dtype=float).ravel(),
        (0.0, 0.01),
        x0,
        method="DOP853",
        rtol=1e-13,
        atol=1e-13,
    )
    errors = []
    for i, dt in enumerate((0.01 / 40, 0.01 / 80, 0.01 / 160)):
        plant = fc.Plant(arm, x0, sample_time=0.01, dt=dt)
        y = plant.step(u)
        errors.append(np.max(np.abs(plant.state - sol.y[:, -1])))
        if i == 0:
            np.testing.assert_array_equal(y, plant.state)  # no measurements given: the state
            assert plant.time == pytest.approx(0.01)
            inputs = plant.trajectory().inputs
            np.testing.assert_array_equal(inputs[:-1], np.tile(held, (40, 1)))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 12) & (ratios < 20)), ratios  # RK4: 2^4 per halving
    assert errors[-1] < 1e-5


def test_measurements_by_name_are_the_models_outputs(arm):
    names = ("q1", "q2", "q3", "dq1", "dq2", "dq3", "tip_x", "tip_y")
    x0 = np.r_[np.radians([10.0, -5.0, 3.0]), 1e-3, -2e-3, 1e-3, 0.1, 0.0, -0.2, 0.0, 0.0, 0.0]
    plant = fc.Plant(arm, x0, sample_time=0.01, measurements=names)
    assert plant.measurement_names == names
    y = plant.output()
    tip = np.array(arm.functions["tip"](x0[: arm.n_q], x0[arm.n_q :])[0], dtype=float).ravel()
    np.testing.assert_allclose(y, np.r_[x0[:3], x0[arm.n_q : arm.n_q + 3], tip], atol=1e-14)


def test_seeded_noise_repeats_and_has_the_sensors_levels(arm):
    ctrl = fc.design(arm, fc.equilibrium(arm, TARGET), fc.load_controller("lqg"))
    plants = [fc.Plant.for_controller(arm, ctrl, TARGET, noise=7) for _ in range(2)]
    exact = fc.Plant.for_controller(arm, ctrl, TARGET).output()
    draws = np.array([plants[0].output() for _ in range(4000)])
    np.testing.assert_array_equal(draws[0], plants[1].output())
    std = np.std(draws - exact, axis=0)
    np.testing.assert_allclose(std, ctrl.sensors.noise_std, rtol=0.06)


@pytest.mark.parametrize(
    "kwargs, key",
    [
        (dict(x0=[0.0, 0.0]), "x0"),
        (dict(sample_time=0.0), "sample_time"),
        (dict(dt=0.003), "dt"),
        (dict(measurements=("q1", "speed")), "measurements"),
        (dict(measurements=("dq1", "q1")), "measurements"),
        (dict(noise=0.1), "noise"),
    ],
)
def test_bad_arguments_name_the_key(arm, kwargs, key):
    args = {"x0": np.zeros(3), "sample_time": 0.01, **kwargs}
    with pytest.raises(SpecError) as info:
        fc.Plant(arm, args.pop("x0"), **args)
    assert info.value.key == key


def test_bad_torques_are_refused_and_a_diverging_state_raises(arm):
    plant = fc.Plant(arm, np.zeros(3), sample_time=0.01, saturate=False)
    for u in ([1.0, 2.0], [np.nan, 0.0, 0.0]):
        with pytest.raises(SpecError) as info:
            plant.step(u)
        assert info.value.key == "u"
    assert plant.time == 0.0
    with pytest.raises(SimulationError, match="not finite"):
        for _ in range(100):
            plant.step([1e12, -1e12, 1e12])


def test_an_lqg_set_to_hold_rides_through_sensor_glitches(arm, move):
    """Every 40th measurement is lost during the move: held (NaN, predicted through), the tip
    stays within the 1 mm settling band of the clean run's path, and well inside what the
    naive repair (repeating the last measurement) gives."""
    import dataclasses

    settings = dataclasses.replace(fc.load_controller("lqg"), on_bad_measurement="hold")
    tips = {}
    for mode in ("clean", "hold", "repeat"):
        ctrl = fc.design(arm, fc.equilibrium(arm, TARGET), settings)
        ctrl.set_reference(move)
        ctrl.reset()
        plant = fc.Plant.for_controller(arm, ctrl, move.start)
        y = last = plant.output()
        lost = 0
        for k in range(math.ceil(4.0 / ctrl.sample_time - 1e-9)):
            if mode != "clean" and k % 40 == 39:
                y = np.full_like(y, np.nan) if mode == "hold" else last
                lost += 1
            last = y
            y = plant.step(ctrl.step(plant.time, y))
        assert ctrl.stats.status["held"] == (lost if mode == "hold" else 0)
        tips[mode] = plant.trajectory().tip
    assert lost > 10
    off = {m: np.max(np.linalg.norm(tips[m] - tips["clean"], axis=1)) for m in ("hold", "repeat")}
    assert off["hold"] < 1e-3 and off["hold"] < 0.25 * off["repeat"], off
