"""The linear verdict for every linear controller: PD, LQR, LQG, MPC, against independent checks."""

from __future__ import annotations

import numpy as np
import pytest
from support import DATA

import flexctrl as fc
from flexctrl.linear import Linearizer, discretize
from flexctrl.loop.mismatch import plant_sensors
from flexctrl.loop.verdict import closed_loop_matrix, linear_closed_loop_radius

MODEL = DATA / "models" / "subedi3link.toml"
TARGET = np.radians([30.0, 0.0, 0.0])


def _model(payload: float):
    return fc.load_model(
        MODEL,
        payload=payload,
        fidelity="amm:2",
        gravity=[0.0, 0.0],
        overrides={f"links[{i}].damping_ratio": 0.005 for i in (1, 2, 3)},
    )


@pytest.fixture(scope="module")
def nominal():
    model = _model(2.0)
    return model, fc.equilibrium(model, TARGET)


def test_full_state_radius_is_the_spectral_radius_of_ad_minus_bd_k(nominal):
    import control

    model, op = nominal
    lqr = fc.design(
        model,
        op,
        fc.load_controller(DATA / "controllers" / "lqr.toml", ["sensors.outputs=['state']"]),
    )
    A, B, _C, _D = Linearizer(model, ("joints",)).matrices(op)
    sysd = discretize(control.ss(A, B, np.eye(A.shape[0]), 0), lqr.sample_time)
    direct = np.max(np.abs(np.linalg.eigvals(np.asarray(sysd.A) - np.asarray(sysd.B) @ lqr.K)))
    assert linear_closed_loop_radius(model, lqr, TARGET) == pytest.approx(direct, rel=1e-9)


def test_observer_loop_has_the_separation_principles_poles_on_the_design_model(nominal):
    """On its own model an LQG loop's poles are the regulator's and the estimator's (separation)."""
    import control

    model, op = nominal
    lqg = fc.design(model, op, fc.load_controller(DATA / "controllers" / "lqg.toml"))
    A, B, C, D = Linearizer(model, lqg.sensors).matrices(op)
    sysd = discretize(control.ss(A, B, np.eye(A.shape[0]), 0), lqg.sample_time)
    Ad, Bd = np.asarray(sysd.A), np.asarray(sysd.B)
    poles = np.linalg.eigvals(closed_loop_matrix(Ad, Bd, C, D, lqg.linear_law(TARGET)))
    expected = np.r_[np.linalg.eigvals(Ad - Bd @ lqg.K), lqg.observer.poles]
    top = np.sort(np.abs(poles))[::-1][: expected.size]
    np.testing.assert_allclose(top, np.sort(np.abs(expected))[::-1], rtol=1e-6, atol=1e-9)


def test_pd_radius_predicts_the_decay_rate_of_the_nonlinear_run():
    """The slowest pole of the PD loop sets how fast a small joint error dies out in the run."""
    model = _model(2.0)
    target = TARGET + np.radians([0.5, 0.0, 0.0])
    start = DATA / "studies" / "tuning" / "start" / "pd.toml"  # the untuned 1 Hz PD: a fixed file
    pd = fc.design(model, fc.equilibrium(model, target), fc.load_controller(start))
    radius = linear_closed_loop_radius(model, pd, target)
    assert 0.99 < radius < 1.0  # slow (a 1 Hz PD sampled at 1 kHz), but stable
    res = fc.closed_loop(model, pd, fc.Move(start=TARGET, target=target, time=0.3), duration=8.0)
    assert res.metrics["closed_loop_radius"] == radius
    t, error = res.trajectory.time, np.abs(res.trajectory.states[:, 0] - target[0])
    blocks = [
        (t[i], error[i : i + 200].max()) for i in np.flatnonzero((t >= 4.0) & (t < 7.8))[::200]
    ]
    times, envelope = np.array(blocks).T
    measured = np.polyfit(times, np.log(envelope), 1)[0]  # 1/s
    assert measured == pytest.approx(np.log(radius) / pd.sample_time, rel=0.03)


@pytest.mark.parametrize("payload, stable", [(0.0, False), (2.0, True)], ids=["0kg", "2kg"])
def test_verdict_and_simulation_agree_off_the_design_payload(payload, stable):
    """A 2 kg LQG: unstable on the 0 kg arm by the linear verdict and by the run; stable at 2 kg.

    The 0 kg cell must be unstable in both (the run diverges, not merely settles slowly), so a
    regression that makes either side stable fails here.
    """
    design, plant = _model(2.0), _model(payload)
    op = fc.equilibrium(design, TARGET)
    lqg = fc.design(design, op, fc.load_controller(DATA / "controllers" / "lqg.toml"))
    sensors = plant_sensors(plant, lqg.sensors, tuple(TARGET))
    radius = linear_closed_loop_radius(plant, lqg, TARGET, sensors)
    move = fc.Move(start=np.radians([0, 0, 0]), target=TARGET, time=1.5)
    res = fc.closed_loop(design, lqg, move, duration=6.0, plant=plant, on_divergence="record")
    assert (radius < 1.0) is stable and bool(res.metrics["stable"]) is stable
    assert res.metrics["closed_loop_radius"] == radius
    assert (res.metrics["divergence_time"] < 6.0) is not stable


def test_nmpc_has_no_linear_verdict(nominal):
    """The NMPC solves a nonlinear programme per sample: no linear law, no linear verdict."""
    from flexctrl.control import has_linear_law

    model, op = nominal
    nmpc = fc.design(model, op, fc.NMPCSettings(compile=False, horizon=5))
    assert linear_closed_loop_radius(model, nmpc, TARGET) is None
    assert not has_linear_law("nmpc") and has_linear_law("mpc")
