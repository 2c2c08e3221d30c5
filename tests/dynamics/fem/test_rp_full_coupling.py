"""R-P arm with full coupling (Pan et al. 1990, Eq 43): theta and W among the unknowns."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from full_coupling_checks import check_constraint_derivatives, check_rigid_limit
from scipy.linalg import eigh, null_space
from support import DATA

from flexctrl.beam.elements import hermite_shape, locate
from flexctrl.dynamics.fem.rp_arm import RPArmModel, RPMotion, simulate_rp_arm
from flexctrl.dynamics.fem.rp_arm_full import RPArmFullModel, RPForces, simulate_rp_arm_full
from flexctrl.errors import SimulationError, SpecError
from flexctrl.spec.fem_models import load_rp_arm

SPEC = load_rp_arm(DATA / "models" / "rp_arm.toml")
MOTION = RPMotion(C1=0.3, C2=-0.4, T=0.6, theta0=0.0, dtheta=math.radians(60.0))


@pytest.fixture(scope="module")
def motion_run():
    return simulate_rp_arm_full(SPEC, MOTION, 4, dt=1e-3, duration=0.8)


def test_motion_drive_is_the_partial_coupling_model(motion_run):
    """With theta(t), W(t) imposed by constraints the nodal equations of the Lagrangian are Eq 42's,
    which rp_arm's partial model codes independently (numpy, Pan's K_g): same response.  The only
    difference is that Newmark + Baumgarte tracks the imposed joint motion to O(dt^2) (measured
    ~1e-6 rad), which perturbs the tip by O(dt^2) as well (7e-9 m against a 1.3 mm peak)."""
    full = motion_run
    part = simulate_rp_arm(SPEC, MOTION, 4, dt=1e-3, duration=0.8)
    peak = np.abs(part.tip_y).max()
    assert peak > 5e-4
    joint_err = max(
        np.abs(full.theta - MOTION.theta(full.t)).max(), np.abs(full.W - MOTION.W(full.t)).max()
    )
    assert joint_err < 1e-5
    assert np.abs(full.tip_y - part.tip_y).max() < 1e-4 * peak
    np.testing.assert_allclose(full.lam, part.lam, rtol=0, atol=1e-4 * np.abs(part.lam).max())
    # the needed torque/force are not trivial: they accelerate the housing and the link
    assert np.abs(full.torque).max() > 1.0 and np.abs(full.force).max() > 0.5


def test_recorded_torque_and_force_reproduce_the_motion(motion_run):
    """(a) Feed the joint multipliers of the motion run back as inputs.  On the same time grid
    Newmark solves the same equations (the multiplier moves to the right side), so the motion is
    reproduced to the Newton tolerance (1e-10 relative; bound 1e-9).  At half the step with the
    inputs interpolated linearly, the difference is a discretisation error: it must stay within
    3x the motion run's own O(dt^2) deviation from the prescribed theta(t), W(t)."""
    ref = motion_run
    forces = RPForces.from_samples(ref.t, ref.torque, ref.force, theta0=MOTION.theta0, W0=MOTION.C1)
    same = simulate_rp_arm_full(SPEC, forces, 4, dt=1e-3, duration=0.8)
    assert np.abs(same.theta - ref.theta).max() < 1e-9 and np.abs(same.W - ref.W).max() < 1e-9
    assert np.abs(same.tip_y - ref.tip_y).max() < 1e-9
    half = simulate_rp_arm_full(SPEC, forces, 4, dt=5e-4, duration=0.8)
    tracking = max(
        np.abs(ref.theta - MOTION.theta(ref.t)).max(), np.abs(ref.W - MOTION.W(ref.t)).max()
    )
    assert np.abs(half.theta - MOTION.theta(half.t)).max() < 3 * tracking
    assert np.abs(half.W - MOTION.W(half.t)).max() < 3 * tracking
    assert np.abs(half.tip_y[::2] - ref.tip_y).max() < 1e-3 * np.abs(ref.tip_y).max()


def test_rigid_limit_follows_the_rigid_rp_equations():
    """(b) EI x 1e4: theta and W follow the rigid R-P arm (solve_ivp, tight tolerances) to within
    the Newmark error, which halving dt cuts by ~4; with the file's EI the flexible arm is
    measurably different (the check can fail)."""
    check_rigid_limit(SPEC, W0=0.4)


def _independent_momentum_energy(model, z, zd):
    """Angular momentum about joint 1 and kinetic energy from the material velocities, by 5-point
    Gauss quadrature per element, with the exact axial shortening s(x) = 1/2 int_0^x w'^2."""
    s, L, n, le = model.spec, model.spec.length, model.n, model.le
    q, qd, th_d, W, Wd = z[: model.ne], zd[: model.ne], zd[model.ith], z[model.iW], zd[model.iW]
    rE = s.support_outer - L + W
    gx, gw = np.polynomial.legendre.leggauss(5)
    H = (s.hub_inertia + s.carriage_mass * rE**2) * th_d
    T = 0.5 * s.hub_inertia * th_d**2 + 0.5 * s.carriage_mass * (Wd**2 + rE**2 * th_d**2)
    sh, sh_d = 0.0, 0.0  # s and ds/dt at the left node of the element
    for j in range(n):
        zeta = 0.5 * le * (gx + 1)
        idx = slice(2 * j, 2 * j + 4)
        w, wt = hermite_shape(zeta, le, 0) @ q[idx], hermite_shape(zeta, le, 0) @ qd[idx]
        # s(x) within the element by cumulative quadrature on a fine sub-grid
        fine = np.linspace(0, le, 401)
        d_f, dt_f = hermite_shape(fine, le, 1) @ q[idx], hermite_shape(fine, le, 1) @ qd[idx]
        s_f = sh + np.concatenate(
            [[0], np.cumsum(0.25 * (d_f[1:] ** 2 + d_f[:-1] ** 2) * np.diff(fine))]
        )
        st_f = sh_d + np.concatenate(
            [[0], np.cumsum(0.5 * (d_f[1:] * dt_f[1:] + d_f[:-1] * dt_f[:-1]) * np.diff(fine))]
        )
        sg, stg = np.interp(zeta, fine, s_f), np.interp(zeta, fine, st_f)
        x = j * le + zeta
        px, py = rE + x - sg, w
        vx, vy = Wd - stg - th_d * w, wt + th_d * px
        wts = 0.5 * le * gw * s.mass_per_length
        H += np.sum(wts * (px * vy - py * vx))
        T += 0.5 * np.sum(wts * (vx**2 + vy**2))
        sh, sh_d = s_f[-1], st_f[-1]
    # payload at H: w, w_t at the last node; s(L), s_t(L) from the cumulative sums
    px, py = rE + L - sh, q[2 * n]
    vx, vy = Wd - sh_d - th_d * py, qd[2 * n] + th_d * px
    H += s.payload_mass * (px * vy - py * vx)
    T += 0.5 * s.payload_mass * (vx**2 + vy**2)
    return H, T


def _first_mode(model, amplitude):
    """First free-vibration mode on the t = 0 supports (null space of the support rows), scaled
    to ``amplitude`` (m) at its largest nodal deflection; also its circular frequency (rad/s)."""
    Z = null_space(model.problem().phi_q(None, 0.0))
    lam, V = eigh(Z.T @ model.K @ Z, Z.T @ model.M @ Z)
    v = Z @ V[:, 0]
    return v * amplitude / np.abs(v[::2]).max(), math.sqrt(lam[0])


def test_free_motion_conserves_angular_momentum_and_energy():
    """(c) No gravity, no torque, no force; spinning at 2 rad/s, sliding out at 0.1 m/s, the link
    released in its first mode (2 mm): the angular momentum about joint 1 (computed independently
    from the material velocities by quadrature) and T + V are constants of the motion.

    Tolerances: the model's T and p_theta differ from the quadrature only by the terms of third
    order that the Lagrangian drops (relative size ~ max w'^2).  Trapezoidal Newmark conserves
    neither exactly here (nonlinear, and the supports slide along the vibrating link): the drift
    is O(dt^2) with the phase error of the first mode, ~ (omega_1 dt)^2 / 12 per unit energy; the
    bound is (omega_1 dt)^2 / 4 and halving dt must cut the drift ~4x."""
    spec = dataclasses.replace(SPEC, payload_mass=0.2)
    forces = RPForces(
        torque=lambda t: 0.0, force=lambda t: 0.0, theta0=0.0, W0=0.3, thetad0=2.0, Wd0=0.1
    )
    shape, omega1 = _first_mode(RPArmModel(spec, RPMotion(0.3, 0.0, 1.0), 4), 2e-3)
    drift = {}
    for dt in (1e-3, 5e-4):
        res = simulate_rp_arm_full(spec, forces, 4, dt=dt, duration=0.5, initial_q=shape)
        m = res.model
        z = np.column_stack([res.q, res.theta, res.W])
        zd = np.column_stack([res.qd, res.thetad, res.Wd])
        TV = np.array([m.energies(a, b) for a, b in zip(z, zd)])
        E = TV.sum(axis=1)
        ind = np.array([_independent_momentum_energy(m, a, b) for a, b in zip(z, zd)])
        p_theta = np.array([m.momentum(a, b)[m.ith] for a, b in zip(z, zd)])
        third_order = (res.q[:, 1::2] ** 2).max()
        assert 1e-6 < third_order < 1e-4
        np.testing.assert_allclose(ind[:, 1], TV[:, 0], rtol=third_order)
        np.testing.assert_allclose(ind[:, 0], p_theta, rtol=third_order)
        drift[dt] = (np.ptp(ind[:, 0]) / abs(ind[0, 0]), np.ptp(E) / E[0])
        assert res.W[-1] > 0.3 + 0.2  # the link slides out, theta' drops
        assert res.thetad[-1] < 0.8 * res.thetad[0]
        assert drift[dt][1] < (omega1 * dt) ** 2 / 4
        assert drift[dt][0] < 1e-4
    assert drift[1e-3][0] / drift[5e-4][0] > 3.0 and drift[1e-3][1] / drift[5e-4][1] > 3.0


def test_constraint_derivatives_match_finite_differences():
    """h (Eq 47), h_z, h_zd and Phi_z of the W-dependent support rows against central
    differences."""
    model = RPArmFullModel(SPEC, RPForces.sine(1.0, 1.0, 1.0, W0=0.33), 4)
    check_constraint_derivatives(model, W=0.33, seed=1)
    z = np.r_[np.zeros(model.ne), 0.4, 0.33]
    prob = model.problem()
    j, _ = locate(SPEC.length - 0.33, 4, SPEC.length)
    assert (
        np.flatnonzero(prob.phi_q(z, 0)[1, : model.ne]).min() == 2 * j
    )  # the row sits in the support's element


def test_errors():
    with pytest.raises(SpecError, match="W\\(0\\)"):
        RPArmFullModel(SPEC, RPForces.sine(1.0, 1.0, 1.0, W0=0.9), 4)
    push = RPForces(torque=lambda t: 0.0, force=lambda t: 20.0, W0=0.6)
    with pytest.raises(SimulationError, match="slid off the link"):
        simulate_rp_arm_full(SPEC, push, 4, dt=1e-3, duration=1.0)


def test_scenes_with_a_drive_table(tmp_path):
    """``[drive] kind = "force"`` runs full coupling; ``kind = "motion", coupling = "full"`` reports
    the torque and force the motion needs; inapplicable keys are errors naming file and key."""
    from flexctrl.scenes.run_fem_scene import run_fem_scene
    from flexctrl.spec.overrides import apply_overrides
    from flexctrl.spec.reader import read_toml

    force_scene = DATA / "studies" / "scenes" / "rp_torque_force.toml"
    doc = apply_overrides(read_toml(force_scene), ["duration=0.2"])
    summary = run_fem_scene(doc, str(force_scene), tmp_path, None)
    data = np.genfromtxt(tmp_path / "trajectory.csv", delimiter=",", names=True)
    assert data.dtype.names[-2:] == ("torque", "force")
    assert data["torque"][50] == pytest.approx(
        doc["drive"]["torque_amplitude"] * math.sin(2 * math.pi * 0.05)
    )
    assert data["theta"][-1] > 0 and summary["max_phi_violation_m"] < 1e-6
    motion_scene = DATA / "studies" / "scenes" / "rp_extend_rotate.toml"
    doc = apply_overrides(
        read_toml(motion_scene), ["duration=0.2", "drive.coupling='full'", "n_elements=4"]
    )
    run_fem_scene(doc, str(motion_scene), tmp_path / "m", None)
    data = np.genfromtxt(tmp_path / "m" / "trajectory.csv", delimiter=",", names=True)
    assert np.abs(data["torque"]).max() > 0.1
    for override, key in (
        ("C2=0.2", "C2"),
        ("rotation=10.0", "rotation"),
        ("drive.torque=1.0", "drive.torque"),
    ):
        bad = apply_overrides(read_toml(force_scene), [override])
        with pytest.raises(SpecError, match=f"rp_torque_force.toml: key '{key}'"):
            run_fem_scene(bad, str(force_scene), None, None)
