"""Operating points, linearisation, discretisation and modal facts, checked against independent
computations."""

from __future__ import annotations

import math

import control
import numpy as np
import pytest
import scipy.linalg
from support_models import spring_pendulum

from flexctrl import linear as L
from flexctrl.beam.clamped_mass import clamped_mass_modes
from flexctrl.dynamics.amm import build_amm
from flexctrl.errors import SpecError
from flexctrl.scenes.model_files import load_model
from flexctrl.spec.arm import arm_from_document


def one_link_arm(
    n_modes: int = 3, payload: float = 0.8, gravity: float = -9.81, damping: float = 0.0
):
    """A single flexible link on a hub (joint angle + modal coordinates), built by the
    assumed-modes code."""
    doc = {
        "name": "onelink",
        "gravity": [0.0, gravity],
        "payload": {"mass": payload, "inertia": 2.0e-3},
        "links": [
            {
                "length": 1.2,
                "mass_per_length": 1.5,
                "EI": 900.0,
                "inertia": 1.5 * 1.2**3 / 12,
                "n_modes": n_modes,
                "damping_ratio": damping,
            }
        ],
        "joints": [{"hub_mass": 0.0, "hub_inertia": 0.01, "torque_limit": 40.0}],
    }
    arm = arm_from_document(doc, "onelink.toml")
    return arm, build_amm(arm, n_modes)


@pytest.fixture(scope="module")
def arm3():
    return load_model("models/subedi3link.toml", fidelity="amm:2")


def central_jacobians(model, x, u, h=1e-6):
    f = lambda xx, uu: np.array(model.functions["f"](xx, uu), dtype=float).ravel()  # noqa: E731
    A = np.column_stack([(f(x + h * e, u) - f(x - h * e, u)) / (2 * h) for e in np.eye(x.size)])
    B = np.column_stack([(f(x, u + h * e) - f(x, u - h * e)) / (2 * h) for e in np.eye(u.size)])
    return A, B


def test_equilibrium_balances_gravity_and_stiffness():
    _arm, model = one_link_arm()
    op = L.equilibrium(model, [0.4])
    assert op.kind == "equilibrium" and op.iterations >= 1
    xdot = np.array(model.functions["f"](op.x, op.u), dtype=float).ravel()
    assert np.max(np.abs(xdot)) < 1e-9
    # independent: joint torque = g(q)[0] (K has no joint rows), elastic rows g_f + K_ff q_f = 0
    g = model.gravity(op.q)
    K = np.array(model.functions["K"]()["K"])
    assert op.u[0] == pytest.approx(g[0], rel=1e-12)
    np.testing.assert_allclose(g[1:] + K[1:, 1:] @ op.q[1:], 0.0, atol=1e-9)
    assert np.any(np.abs(op.q[1:]) > 1e-6)  # the link sags


def test_equilibrium_rejects_wrong_joint_count():
    _arm, model = one_link_arm()
    with pytest.raises(SpecError, match="expected 1"):
        L.equilibrium(model, [0.1, 0.2])


@pytest.mark.parametrize("builder", ["toy", "onelink"])
def test_linearization_matches_central_differences(builder):
    model = (
        spring_pendulum(k=2.0e3, zeta=0.02, friction=0.1)
        if builder == "toy"
        else one_link_arm(damping=0.01)[1]
    )
    rng = np.random.default_rng(3)
    n, N = model.n_u, model.n_q
    amplitude = np.r_[np.full(n, 0.3), np.full(N - n, 1e-3), np.full(n, 0.3), np.full(N - n, 1e-2)]
    x = rng.normal(size=model.n_x) * amplitude
    u = rng.normal(scale=2.0, size=model.n_u)
    op = L.operating_point(model, x, u)
    sys = L.linearize(model, op, outputs=("joints",))
    A_fd, B_fd = central_jacobians(model, op.x, op.u, h=1e-6)
    _, B_big = central_jacobians(model, op.x, op.u, h=1.0)  # f is affine in u: any step is exact
    np.testing.assert_allclose(sys.A, A_fd, atol=1e-6 * np.max(np.abs(A_fd)))
    np.testing.assert_allclose(sys.B, B_big, rtol=1e-10, atol=1e-12 * np.max(np.abs(B_big)))
    np.testing.assert_allclose(sys.B, B_fd, atol=1e-6 * np.max(np.abs(B_fd)))


def test_linearization_of_three_link_arm_matches_central_differences(arm3):
    op = L.equilibrium(arm3, np.radians([80.0, -10.0, -10.0]))
    x = op.x + np.r_[np.zeros(9), 0.05 * np.ones(9)]  # moving, so the Coriolis terms count
    op2 = L.operating_point(arm3, x, op.u + 1.0)
    sys = L.linearize(arm3, op2, outputs=("joints", "strain", "tip"))
    A_fd, B_fd = central_jacobians(arm3, op2.x, op2.u, h=1e-7)
    rel = np.max(np.abs(sys.A - A_fd)) / np.max(np.abs(A_fd))
    assert rel < 1e-6
    np.testing.assert_allclose(sys.B, B_fd, rtol=1e-5, atol=1e-6 * np.max(np.abs(B_fd)))


def test_signal_names(arm3):
    op = L.equilibrium(arm3, np.radians([80.0, -10.0, -10.0]))
    sys = L.linearize(arm3, op, outputs=("tip", "strain", "joints"))
    assert sys.state_labels[:4] == ["q1", "q2", "q3", "qf11"]
    assert sys.state_labels[9:13] == ["dq1", "dq2", "dq3", "dqf11"]
    assert sys.input_labels == ["tau1", "tau2", "tau3"]
    assert sys.output_labels == ["q1", "q2", "q3", "kappa1", "kappa2", "kappa3", "tip_x", "tip_y"]


def test_output_jacobians_match_finite_differences():
    _arm, model = one_link_arm(n_modes=2)
    op = L.operating_point(model, np.array([0.3, 0.01, -0.002, 0.4, 0.1, -0.3]), np.array([5.0]))
    sensors = L.Sensors.build(model, ("joints", "strain", "tip", "tip_acc", "deflection"))
    sys = L.linearize(model, op, outputs=sensors)
    y = lambda x, u: sensors.evaluate(x, u)  # noqa: E731
    h = 1e-6
    C_fd = np.column_stack(
        [(y(op.x + h * e, op.u) - y(op.x - h * e, op.u)) / (2 * h) for e in np.eye(model.n_x)]
    )
    D_fd = np.column_stack(
        [(y(op.x, op.u + h * e) - y(op.x, op.u - h * e)) / (2 * h) for e in np.eye(model.n_u)]
    )
    np.testing.assert_allclose(sys.C, C_fd, atol=1e-6 * (1 + np.max(np.abs(C_fd))))
    np.testing.assert_allclose(sys.D, D_fd, atol=1e-6 * (1 + np.max(np.abs(D_fd))))
    assert np.any(np.abs(sys.D) > 0)  # the accelerometer feels the torque


def test_strain_gauge_is_root_curvature_of_the_mode_shapes():
    arm, model = one_link_arm(n_modes=2)
    modes = clamped_mass_modes(
        1.2, 1.5, 900.0, 2, m_tip=arm.payload.mass, J_tip=arm.payload.effective_inertia
    )
    qf = np.array([0.02, -0.004])
    x = np.r_[0.1, qf, np.zeros(3)]
    sensors = L.Sensors.build(model, ("strain",))
    kappa = sensors.evaluate(x, [0.0])[0]
    # w''(0) from the beam module's own second derivative at the root
    assert kappa == pytest.approx(float(modes.shape(0.0, derivative=2) @ qf), rel=1e-9)
    # and from the deflection shape near the clamped root (w = w' = 0 there):
    # w(h) = a h^2/2 + b h^3/6 + O(h^4)  =>  a = (8 w(h) - w(2h)) / (2 h^2) + O(h^2)
    h = 1e-3
    w1, w2 = modes.shape(np.array([h, 2 * h])).T @ qf
    assert kappa == pytest.approx((8 * w1 - w2) / (2 * h * h), rel=1e-5)


def test_strain_needs_mode_shapes():
    with pytest.raises(SpecError, match="root curvature"):
        L.Sensors.build(spring_pendulum(), ("strain",))


def test_sensor_noise_is_added_with_the_stated_deviation():
    model = spring_pendulum()
    sensors = L.Sensors.build(model, ("joints",), {"joints": 0.01})
    rng = np.random.default_rng(0)
    x = np.zeros(6)
    samples = np.array([sensors.measure(x, [0, 0], rng) for _ in range(4000)])
    assert samples.std(axis=0) == pytest.approx([0.01, 0.01], rel=0.05)
    assert np.all(sensors.measure(x, [0, 0]) == 0.0)


def test_discretisation_matches_expm_of_augmented_matrix():
    model = spring_pendulum(k=5.0e3, zeta=0.01)
    op = L.equilibrium(model, [0.3, -0.4])
    sys = L.linearize(model, op, outputs=("joints", "tip"))
    dt = 0.004
    sysd = L.discretize(sys, dt)
    n, m = sys.nstates, sys.ninputs
    aug = np.zeros((n + m, n + m))
    aug[:n, :n], aug[:n, n:] = sys.A, sys.B
    E = scipy.linalg.expm(aug * dt)
    np.testing.assert_allclose(sysd.A, E[:n, :n], atol=1e-12)
    np.testing.assert_allclose(sysd.B, E[:n, n:], atol=1e-12)
    np.testing.assert_allclose(sysd.C, sys.C)
    assert sysd.dt == dt
    assert sysd.state_labels == sys.state_labels and sysd.output_labels == sys.output_labels


def test_modal_summary_recovers_a_damped_oscillator():
    wn, zeta = 2 * math.pi * 7.0, 0.05
    sys = control.ss([[0, 1], [-(wn**2), -2 * zeta * wn]], [[0], [1]], [[1, 0]], 0)
    summary = L.modal_summary(sys)
    assert summary.frequency_hz == pytest.approx([7.0])
    assert summary.damping == pytest.approx([zeta])
    discrete = L.modal_summary(L.discretize(sys, 0.002))
    assert discrete.frequency_hz == pytest.approx([7.0], rel=1e-9)
    assert discrete.damping == pytest.approx([zeta], rel=1e-9)


def test_locked_frequencies_of_one_link_equal_clamped_mass_beam():
    arm, model = one_link_arm(n_modes=4, payload=0.8)
    op = L.equilibrium(model, [0.7])
    beam = clamped_mass_modes(
        1.2, 1.5, 900.0, 4, m_tip=arm.payload.mass, J_tip=arm.payload.effective_inertia
    )
    np.testing.assert_allclose(L.locked_frequencies(model, op), beam.frequency_hz, rtol=1e-9)


def test_locked_frequencies_converge_with_modes_on_three_link_arm():
    q = np.radians([80.0, -10.0, -10.0])
    firsts = []
    for nm in (1, 2, 3):
        model = load_model("models/subedi3link.toml", fidelity=f"amm:{nm}")
        x = np.r_[q, np.zeros(model.n_x - 3)]  # undeflected: the same configuration for every basis
        f = L.locked_frequencies(model, L.operating_point(model, x, np.zeros(3)))
        firsts.append(f[:3])
    firsts = np.array(firsts)
    # Rayleigh-Ritz on nested bases (the first modes are the same functions): more modes never
    # raise a frequency, and the changes shrink
    assert np.all(firsts[1] <= firsts[0] * (1 + 1e-9)) and np.all(
        firsts[2] <= firsts[1] * (1 + 1e-9)
    )
    assert np.max(np.abs(firsts[2] - firsts[1]) / firsts[2]) < np.max(
        np.abs(firsts[1] - firsts[0]) / firsts[1]
    )
    assert np.max(np.abs(firsts[2] - firsts[1]) / firsts[2]) < 0.02
