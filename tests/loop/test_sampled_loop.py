"""The sampled-data loop against independent computations."""

from __future__ import annotations

import numpy as np
import pytest
from support import DATA

from flexctrl.control.controller import Controller
from flexctrl.dynamics.build import build_model
from flexctrl.errors import SimulationError, SpecError
from flexctrl.linear import Sensors, equilibrium
from flexctrl.loop.sampled import simulate_closed_loop
from flexctrl.sim import simulate
from flexctrl.spec.arm import load_arm


class _Schedule(Controller):
    """Applies a pre-set torque sequence (one row per sample) whatever it measures."""

    kind = "schedule"

    def __init__(self, torques, sample_time, sensors, limits, op):
        class _S:
            pass

        settings = _S()
        settings.sample_time = sample_time
        super().__init__(settings, op, sensors, limits)
        self.torques = torques
        self.k = 0
        self.seen = []

    def _step(self, t, y):
        self.seen.append((t, y.copy()))
        u = self.torques[min(self.k, len(self.torques) - 1)]
        self.k += 1
        return u


@pytest.fixture(scope="module")
def arm_model(model_path=None):
    from support import MODEL

    arm = load_arm(MODEL, overrides=["gravity=[0.0, 0.0]"])
    return build_model(arm.with_modes(1), "amm:1")


def test_zero_order_hold_equals_open_loop_rk4_with_the_same_held_torques(arm_model):
    model = arm_model
    rng = np.random.default_rng(0)
    Ts, dt, samples = 0.01, 0.001, 30
    torques = rng.uniform(-5, 5, (samples, model.n_u))
    op = equilibrium(model, np.zeros(model.n_u))
    sensors = Sensors.build(model, ("joints",))
    ctrl = _Schedule(torques, Ts, sensors, np.full(model.n_u, np.inf), op)
    x0 = np.zeros(model.n_x)
    traj, times = simulate_closed_loop(model, ctrl, x0, samples * Ts, dt, compile=False)
    held = np.repeat(torques, int(round(Ts / dt)), axis=0)
    reference = simulate(model, x0, samples * Ts, dt=dt, method="rk4", u=held, compile=False)
    assert traj.states[-1] == pytest.approx(reference.states[-1], rel=1e-9, abs=1e-12)
    assert times == pytest.approx(np.arange(samples) * Ts)
    # the controller saw the plant's joint angles at each sample instant
    for k, (_t, y) in enumerate(ctrl.seen[1:], start=1):
        assert y == pytest.approx(traj.states[k * 10, : model.n_u], abs=1e-12)


def test_torques_are_clipped_to_the_limits_and_divergence_is_an_error(arm_model):
    model = arm_model
    op = equilibrium(model, np.zeros(model.n_u))
    sensors = Sensors.build(model, ("joints",))
    ctrl = _Schedule(
        np.full((5, model.n_u), 1e3), 0.01, sensors, np.array([200.0, 100.0, 50.0]), op
    )
    traj, _ = simulate_closed_loop(model, ctrl, np.zeros(model.n_x), 0.05, 0.001, compile=False)
    assert np.max(np.abs(traj.inputs), axis=0) == pytest.approx([200.0, 100.0, 50.0])
    crazy = _Schedule(np.full((100, model.n_u), 1e9), 0.01, sensors, np.full(model.n_u, np.inf), op)
    with pytest.raises(SimulationError, match="diverged at t ="):
        simulate_closed_loop(model, crazy, np.zeros(model.n_x), 1.0, 0.001, compile=False)


def test_plant_step_must_divide_the_sample_time(arm_model):
    op = equilibrium(arm_model, np.zeros(arm_model.n_u))
    ctrl = _Schedule(
        np.zeros((1, arm_model.n_u)),
        0.01,
        Sensors.build(arm_model, ("joints",)),
        np.full(3, np.inf),
        op,
    )
    with pytest.raises(SpecError, match="does not divide"):
        simulate_closed_loop(arm_model, ctrl, np.zeros(arm_model.n_x), 0.1, 0.003, compile=False)


def test_divergence_can_stop_the_run_and_be_recorded(arm_model):
    """stop_on_divergence: the trajectory up to the detection, no NaN, and the reason in meta."""
    model = arm_model
    op = equilibrium(model, np.zeros(model.n_u))
    sensors = Sensors.build(model, ("joints",))
    crazy = _Schedule(np.full((100, model.n_u), 1e9), 0.01, sensors, np.full(model.n_u, np.inf), op)
    traj, times = simulate_closed_loop(
        model, crazy, np.zeros(model.n_x), 1.0, 0.001, compile=False, stop_on_divergence=True
    )
    div = traj.meta["divergence"]
    assert div is not None and 0 < div["time"] < 1.0 and "diverged at t =" in div["message"]
    assert np.all(np.isfinite(traj.states)) and traj.time[-1] <= div["time"] + 1e-12
    assert times[-1] < div["time"]
    # a monitor stops a run that stays finite: here any joint beyond 0.01 rad
    gentle = _Schedule(
        np.full((100, model.n_u), 5.0), 0.01, sensors, np.full(model.n_u, np.inf), op
    )

    def monitor(t, x):
        return "joint beyond 0.01 rad" if np.max(np.abs(x[: model.n_u])) > 0.01 else None

    traj, _ = simulate_closed_loop(
        model,
        gentle,
        np.zeros(model.n_x),
        1.0,
        0.001,
        compile=False,
        monitor=monitor,
        stop_on_divergence=True,
    )
    assert traj.meta["divergence"]["reason"] == "joint beyond 0.01 rad"
    assert (
        np.max(np.abs(traj.states[-1, : model.n_u]))
        > 0.01
        > np.max(np.abs(traj.states[-12, : model.n_u]))
    )
    with pytest.raises(SimulationError, match="joint beyond 0.01 rad"):
        simulate_closed_loop(
            model, gentle, np.zeros(model.n_x), 1.0, 0.001, compile=False, monitor=monitor
        )


def test_plant_step_with_constants_as_input_is_shared_across_configurations_and_exact(root):
    import casadi as ca

    from flexctrl.dynamics.parametric import LIFTED, constants_as_parameters
    from flexctrl.loop.plant_step import advance_function, plant_step_function

    arm = load_arm(DATA / "models" / "subedi3link.toml").with_payload(2.0)
    models = [
        build_model(arm, "amm:2", modes="frozen", reference_q=np.radians(q))
        for q in ([0, 30, -60], [0, 120, 45])
    ]
    fps = []
    for m in models:
        LIFTED.clear()  # a lift anew for each model, not the one kept for the first
        fps.append(constants_as_parameters(m.functions["f"]))
    assert all(c.size > 0 for _, c in fps)
    # the two configurations differ only in constant values: one generated code serves both
    texts = []
    for m, (fp, c) in zip(models, fps):
        generator = ca.CodeGenerator("advance.c")
        generator.add(plant_step_function(m, 4, fp, c.size))
        texts.append(generator.dump())
    assert texts[0] == texts[1] and not np.allclose(fps[0][1], fps[1][1])
    embedded_texts = []
    for m in models:
        generator = ca.CodeGenerator("advance.c")
        generator.add(plant_step_function(m, 4))
        embedded_texts.append(generator.dump())
    assert (
        embedded_texts[0] != embedded_texts[1]
    )  # without the parameter every configuration compiles anew
    rng = np.random.default_rng(3)
    for model in models:
        x = np.concatenate([np.radians([10, 20, -30]), rng.normal(0, 1e-3, model.n_x - 3)])
        u = np.array([20.0, -5.0, 3.0])
        shared, _ = advance_function(model, 4, compile=False)
        embedded = plant_step_function(model, 4)  # the model's own constants, no parameter
        a, b = np.array(shared(x, u, 2.5e-4)), np.array(embedded(x, u, 2.5e-4))
        assert np.allclose(a, b, rtol=1e-12, atol=1e-15)
        assert not np.allclose(a[:, -1], x)  # the arm moved: the comparison is not trivial
