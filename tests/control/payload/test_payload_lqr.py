"""The payload-aware LQR: its grid against direct designs, its certificate against the loop's
verdict and nonlinear runs, its estimator against the closed-form rigid-body payload."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from support import scene_arm

import flexctrl as fc
from flexctrl.control.payload.grid import check_certificate, model_with_payload
from flexctrl.loop.mismatch import plant_sensors
from flexctrl.loop.verdict import linear_closed_loop_radius

POSE = np.radians([30.0, 0.0, 90.0])
START = np.radians([0.0, 0.0, 90.0])


arm = scene_arm


def settings(**payload):
    """lqr_payload.toml with a coarser grid (the tests' budget) and ``payload`` changed."""
    s = fc.load_controller("lqr_payload")
    table = dataclasses.replace(s.payload, grid_step=1.0, **payload)
    return dataclasses.replace(s, payload=table)


@pytest.fixture(scope="module")
def ctrl():
    model = arm(2.0)
    c = fc.design(model, fc.equilibrium(model, POSE), settings())
    c.grid  # noqa: B018 (built here, shared by the tests)
    return c


def test_the_gain_at_a_grid_point_is_a_direct_design_there(ctrl):
    plain = dataclasses.replace(ctrl.settings, payload=None)
    for i, m in enumerate(ctrl.grid.payloads):
        model = arm(float(m))
        direct = fc.design(model, fc.equilibrium(model, POSE), plain)
        scale = np.max(np.abs(direct.K))
        np.testing.assert_allclose(ctrl.grid.K[i], direct.K, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(ctrl.grid.M[i], direct.observer.M, rtol=0, atol=1e-9)


def test_the_certificate_is_the_loops_own_verdict(ctrl):
    for i, row in enumerate(ctrl.certificate):
        ctrl.index = i
        for m, radius in zip(row["plant_kg"], row["radius"]):
            plant = arm(m)
            sensors = plant_sensors(plant, ctrl.sensors, tuple(POSE))
            expected = linear_closed_loop_radius(plant, ctrl, POSE, sensors)
            assert radius == pytest.approx(expected, rel=1e-6)
    ctrl.index = 0


def test_a_model_rebuilt_with_a_payload_is_the_loaded_model():
    rebuilt = model_with_payload(arm(2.0), 3.0)
    loaded = arm(3.0)
    q = np.r_[POSE, 0.01 * np.ones(6)]
    np.testing.assert_allclose(rebuilt.mass_matrix(q), loaded.mass_matrix(q), rtol=1e-12)
    assert rebuilt.info["reference_q"] == loaded.info["reference_q"]


def test_a_failing_grid_cell_is_named():
    rows = [
        {"design_kg": 0.0, "plant_kg": (0.0, 0.5, 1.0), "radius": (0.9, 0.95, 0.99), "worst": 0.99},
        {"design_kg": 1.0, "plant_kg": (1.0, 2.0, 3.0), "radius": (0.9, 1.02, 1.1), "worst": 1.1},
    ]
    with pytest.warns(
        UserWarning, match=r"design at 1 kg has closed-loop radius 1.1000 on the 3 kg"
    ):
        failing = check_certificate(rows, "c.toml")
    assert [r["design_kg"] for r in failing] == [1.0]


def test_an_undamped_design_fails_the_certificate_and_names_the_cell():
    """The arm as its file ships it (no structural damping) on a 1 kg grid: a cell fails and
    the warning names it."""
    model = fc.load_model(
        "subedi3link", payload=2.0, fidelity="amm:2", gravity=[0.0, 0.0], reference_q=START
    )
    c = fc.design(model, fc.equilibrium(model, POSE), settings())
    with pytest.warns(UserWarning, match=r"too coarse for the certificate: the design at \d"):
        rows = c.certificate
    assert any(r["worst"] >= 1.0 for r in rows)


def forced(ctrl_settings, design_kg: float):
    """Settings whose estimate never moves from ``design_kg`` (a wrong estimate forced)."""
    return dataclasses.replace(
        ctrl_settings,
        payload=dataclasses.replace(
            ctrl_settings.payload, prior_mean=design_kg, prior_std=1e-3, excitation_rate=1e9
        ),
    )


@pytest.mark.parametrize("design_kg, plant_kg", [(1.0, 1.5), (2.0, 3.0)])
def test_a_wrong_estimate_inside_the_certified_range_degrades_gracefully(ctrl, design_kg, plant_kg):
    """A design lighter than the plant, held: stable as the certificate says, in a nonlinear run."""
    model = arm(2.0)
    c = fc.design(model, fc.equilibrium(model, POSE), forced(ctrl.settings, design_kg))
    move = fc.Move(start=START, target=POSE, time=1.5)
    res = fc.closed_loop(model, c, move, 4.0, plant=arm(plant_kg), on_divergence="record")
    assert c.payload_estimate.design == design_kg
    radius = res.metrics["closed_loop_radius"]
    assert radius < 1.0 and res.metrics["stable"] == 1
    assert res.metrics["tip_residual_rms"] < 0.01


def closed_form_payload(res, rigid_0, rigid_1, window):
    """Least-squares payload from tau = M(q; m) qdd + c(q, qd; m), M and c affine in m.

    From the plant's own states and held torques (qdd by central differences), over the
    samples in ``window`` (s): independent of the bank, its filters and its linearisation.
    """
    t, X, U = res.trajectory.time, res.trajectory.states, res.trajectory.inputs
    n = rigid_0.n_u
    q, qd = X[:, :n], X[:, n:]
    qdd = np.gradient(qd, t, axis=0)
    rows, rhs = [], []
    for k in np.nonzero((t > window[0]) & (t < window[1]))[0][::5]:
        base = rigid_0.mass_matrix(q[k]) @ qdd[k] + rigid_0.coriolis(q[k], qd[k])
        per_kg = rigid_1.mass_matrix(q[k]) @ qdd[k] + rigid_1.coriolis(q[k], qd[k]) - base
        rows.append(per_kg)
        rhs.append(U[k] - base)
    a, b = np.concatenate(rows), np.concatenate(rhs)
    return float(a @ b / (a @ a))


def test_on_the_rigid_arm_the_estimate_is_the_closed_form_payload():
    truth = 1.3
    model = arm(2.0, "rigid")
    s = dataclasses.replace(
        fc.load_controller("lqr_payload"),
        sensors=dataclasses.replace(fc.load_controller("lqr").sensors, outputs=("joints",)),
    )
    c = fc.design(model, fc.equilibrium(model, POSE), s)
    move = fc.Move(start=START, target=POSE, time=1.5)
    res = fc.closed_loop(model, c, move, 4.0, plant=arm(truth, "rigid"))
    exact = closed_form_payload(res, arm(0.0, "rigid"), arm(1.0, "rigid"), (0.05, 1.45))
    estimate = c.payload_estimate
    assert abs(estimate.mean - exact) < 0.2
    assert exact == pytest.approx(truth, abs=0.05)
    assert estimate.design <= truth
    trace = c.payload_trace()
    assert trace["mean"][0] == pytest.approx(c.settings.payload.mean0, abs=1e-9)
    assert res.payload_estimate["mean"][-1] == estimate.mean
    assert res.metrics["payload_estimate_error"] == pytest.approx(abs(estimate.mean - truth))
    labels = [ax.get_ylabel() for ax in res.plot().axes]
    assert "payload estimate (kg)" in labels


def test_before_any_motion_the_estimate_is_the_prior(ctrl):
    ctrl.reset()
    s = ctrl.settings.payload
    assert ctrl.payload_estimate.mean == pytest.approx(s.mean0, abs=0.01)
    low = max(s.range[0], s.mean0 - s.err_light_sigmas * s.std0)
    assert ctrl.payload_estimate.design == ctrl.grid.payloads[ctrl.grid.index_at_or_below(low)]


def test_a_posterior_on_one_grid_payload_designs_there_not_a_step_below(ctrl):
    """The neighbours' leftover probability (1e-9) spreads the posterior by about 1e-5 kg:
    the light side falls just below the grid payload, and the snap keeps the design there."""
    ctrl.reset()
    bank, grid = ctrl.bank, ctrl.grid
    k = 3
    bank.p = np.full(len(grid.payloads), 1e-9)
    bank.p[k] = 1.0
    bank.p /= bank.p.sum()
    assert bank.light_side() < grid.payloads[k]
    assert ctrl._choose(1.0) == k
    step = grid.payloads[k] - grid.payloads[k - 1]
    assert grid.index_at_or_below(grid.payloads[k] - 0.01 * step) == k
    assert grid.index_at_or_below(grid.payloads[k] - 0.05 * step) == k - 1
    ctrl.reset()


def test_a_design_switch_restarts_the_rest_delay(ctrl):
    """A design chosen at rest first tracks at moving gains for rest_delay."""
    ctrl.reset()
    delay = ctrl.settings.payload.rest_delay
    assert ctrl._resting(1.0)  # holding, never moved
    bank = ctrl.bank
    bank.p = np.eye(len(ctrl.grid.payloads))[2]  # a confident estimate: another design
    assert ctrl._choose(1.0) != ctrl.grid.index_at_or_below(0.0)
    assert not ctrl._resting(1.0 + 0.5 * delay)
    assert ctrl._resting(1.0 + delay)
    ctrl.reset()


def test_payload_range_in_python_is_the_files_table():
    model = arm(2.0, "rigid")
    s = fc.load_controller("lqr")
    s = dataclasses.replace(s, sensors=dataclasses.replace(s.sensors, outputs=("joints",)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        c = fc.design(model, fc.equilibrium(model, POSE), s, payload_range=(0.5, 1.5))
    assert c.settings.payload.range == (0.5, 1.5)
    with pytest.raises(fc.SpecError, match="payload_range"):
        fc.design(
            model, fc.equilibrium(model, POSE), fc.load_controller("pd"), payload_range=(0, 1)
        )
    with pytest.raises(fc.SpecError, match="reversed"):
        fc.design(model, fc.equilibrium(model, POSE), s, payload_range=(2.0, 1.0))


def test_the_payload_aware_mpc_unconstrained_is_the_payload_aware_lqr(ctrl):
    """With the DARE terminal cost and no active constraint, each grid MPC's first move is the
    grid LQR's (two designs that share only the grid's linearisation)."""
    model = arm(2.0)
    s = fc.load_controller("mpc_payload")
    s = dataclasses.replace(s, payload=dataclasses.replace(s.payload, grid_step=1.0))
    mpc = fc.design(model, fc.equilibrium(model, POSE), s)
    assert type(mpc).__name__ == "PayloadMPCController"
    for i in range(len(mpc.grid.payloads)):
        mpc.index = i
        H = mpc.linear_law(POSE)[3]
        np.testing.assert_allclose(H, -ctrl.grid.K[i], rtol=1e-6, atol=1e-6 * np.abs(H).max())


def test_without_a_measurement_the_bank_predicts_and_the_estimate_stays():
    model = arm(2.0, "rigid")
    s = fc.load_controller("lqr_payload")
    s = dataclasses.replace(s, sensors=dataclasses.replace(s.sensors, outputs=("joints",)))
    c = fc.design(model, fc.equilibrium(model, POSE), s)
    c.reset()
    for k in range(3):
        c.step(k * c.sample_time, np.r_[START[0] + 0.01 * k, START[1:]])
    p, dx = c.bank.p.copy(), c.bank.dx.copy()
    u = c._hold(3 * c.sample_time)
    assert np.all(np.isfinite(u)) and np.array_equal(c.bank.p, p)
    g = c.grid
    expected = np.einsum("nij,nj->ni", g.A, dx) + np.einsum(
        "nij,nj->ni", g.B, c.u_previous[None, :] - g.u_op
    )
    np.testing.assert_allclose(c.bank.dx, expected, rtol=1e-12, atol=1e-15)
