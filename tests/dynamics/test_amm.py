"""Assumed-modes model (flexctrl.dynamics.amm): structure, rigid limit, derivatives, energy.

Every reference here is computed independently of the model: a recursive
Newton-Euler pass for the rigid arm, Christoffel symbols from the mass matrix,
finite differences, energy balance along a tight integration, and the analytic
pendulum.  Frequency checks are in ``test_amm_frequencies.py``.
"""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import flexctrl
from flexctrl.dynamics.amm import build_amm
from flexctrl.dynamics.build import ModelFamilyUnavailable, build_model
from flexctrl.errors import FlexctrlError, SpecError
from flexctrl.modal.arm_modes import link_modes
from flexctrl.scenes.model_files import load_model
from flexctrl.spec.arm import load_arm
from flexctrl.spec.fidelity import Fidelity


# -- arms ---------------------------------------------------------------------------------
def _arm(model_path, n_links=3):
    arm = load_arm(model_path)
    return dataclasses.replace(
        arm,
        links=arm.links[:n_links],
        joints=arm.joints[:n_links],
        configuration=arm.configuration[:n_links],
    )


def _general_arm(model_path, n_links=3, slender=False):
    """An arm with every term switched on: hub 1 mass, J_l != m L^2/12 (unless ``slender``:
    then J_l = m L^2/12 as for a beam), slanted gravity."""
    arm = _arm(model_path, n_links)
    links = tuple(
        dataclasses.replace(
            l, inertia=l.mass * l.length**2 / 12 if slender else 1.3 * l.inertia + 0.01
        )
        for l in arm.links
    )
    joints = tuple(
        dataclasses.replace(j, hub_mass=j.hub_mass + 0.7, hub_inertia=j.hub_inertia + 0.003)
        for j in arm.joints
    )
    return dataclasses.replace(arm, links=links, joints=joints, gravity=(2.0, -9.0))


def _state(rng, model, deflection=0.01, rate=1.0):
    n, N = model.n_joints, model.n_q
    q = np.concatenate([rng.uniform(-math.pi, math.pi, n), deflection * rng.normal(size=N - n)])
    qd = np.concatenate([rate * rng.normal(size=n), 10 * deflection * rng.normal(size=N - n)])
    return q, qd


# -- independent rigid-body reference: recursive Newton-Euler ------------------------------
def _cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


def _perp(a):
    return np.array([-a[1], a[0]])


def rnea(arm, q, qd, qdd, gravity):
    """Joint torques of the rigid planar chain: hub i (point mass on joint i, rotor J_h),
    link i (mass at L/2, centroidal J_l), payload (mass and J_p at the last tip)."""
    n = arm.n_links
    theta = omega = alpha = 0.0
    origin_acc = np.zeros(2)
    frames = []
    for i in range(n):
        theta, omega, alpha = theta + q[i], omega + qd[i], alpha + qdd[i]
        e = np.array([math.cos(theta), math.sin(theta)])
        frames.append((e, omega, alpha, origin_acc.copy()))
        span = arm.links[i].length * e
        origin_acc = origin_acc + alpha * _perp(span) - omega**2 * span
    tau = np.zeros(n)
    force, moment = np.zeros(2), 0.0  # what joint i+1 exerts on the outer chain
    for i in reversed(range(n)):
        e, omega, alpha, acc0 = frames[i]
        link, joint = arm.links[i], arm.joints[i]
        span = link.length * e
        bodies = [
            (joint.hub_mass, joint.hub_inertia, 0.0 * e),
            (link.mass, link.inertia, 0.5 * span),
        ]
        if i == n - 1:
            bodies.append((arm.payload.mass, arm.payload.effective_inertia, span))
        moment = moment + _cross(span, force)
        for mass, inertia, d in bodies:
            acc = acc0 + alpha * _perp(d) - omega**2 * d
            f_body = mass * (acc - gravity)
            force = force + f_body
            moment = moment + _cross(d, f_body) + inertia * alpha
        tau[i] = moment
    return tau


def rigid_terms(arm, q_r, qd_r):
    n = arm.n_links
    zero, g = np.zeros(n), np.asarray(arm.gravity, dtype=float)
    M = np.column_stack([rnea(arm, q_r, zero, np.eye(n)[k], np.zeros(2)) for k in range(n)])
    c = rnea(arm, q_r, qd_r, zero, np.zeros(2))
    grav = rnea(arm, q_r, zero, zero, g)
    return M, c, grav


# -- tests --------------------------------------------------------------------------------
def test_pendulum_rigid_single_link(model_path):
    arm = dataclasses.replace(_general_arm(model_path, 1), gravity=(0.0, -9.81))
    model = build_model(arm, "rigid")
    link, hub, pay = arm.links[0], arm.joints[0], arm.payload
    L, m = link.length, link.mass
    inertia = (
        hub.hub_inertia + link.inertia + m * L**2 / 4 + pay.mass * L**2 + pay.effective_inertia
    )
    assert model.coordinate_names == ("q1",)
    for q in np.linspace(-3, 3, 7):
        np.testing.assert_allclose(model.mass_matrix([q]), [[inertia]], rtol=1e-12)
        np.testing.assert_allclose(
            model.gravity([q]),
            [9.81 * (m * L / 2 + pay.mass * L) * math.cos(q)],
            rtol=1e-12,
            atol=1e-12,
        )
        np.testing.assert_allclose(model.coriolis([q], [2.0]), [0.0], atol=1e-12)
        tau = 3.0
        qdd = model.forward_dynamics([q], [0.5], [tau])
        np.testing.assert_allclose(
            qdd,
            [(tau - 9.81 * (m * L / 2 + pay.mass * L) * math.cos(q)) / inertia],
            rtol=1e-12,
            atol=1e-12,
        )
    assert model.omega_max == 0.0


@pytest.mark.parametrize("n_links, n_modes", [(1, 2), (2, 1), (3, 0), (3, 2)])
def test_rigid_part_matches_newton_euler(model_path, n_links, n_modes):
    arm = _general_arm(model_path, n_links)
    model = build_amm(arm, n_modes)
    rng = np.random.default_rng(10 * n_links + n_modes)
    n, N = arm.n_links, model.n_q
    for _ in range(5):
        q_r, qd_r = rng.uniform(-math.pi, math.pi, n), rng.normal(size=n)
        q = np.concatenate([q_r, np.zeros(N - n)])
        qd = np.concatenate([qd_r, np.zeros(N - n)])
        M_ref, c_ref, g_ref = rigid_terms(arm, q_r, qd_r)
        scale = np.abs(M_ref).max()
        np.testing.assert_allclose(
            model.mass_matrix(q)[:n, :n], M_ref, rtol=1e-9, atol=1e-12 * scale
        )
        np.testing.assert_allclose(
            model.coriolis(q, qd)[:n], c_ref, rtol=1e-9, atol=1e-9 * (np.abs(c_ref).max() + scale)
        )
        np.testing.assert_allclose(
            model.gravity(q)[:n], g_ref, rtol=1e-9, atol=1e-12 * np.abs(g_ref).max()
        )


@pytest.mark.parametrize("modes", ["frozen", "scheduled"])
def test_mass_matrix_symmetric_positive_definite(model_path, modes):
    model = build_amm(_arm(model_path), 2, modes=modes)
    rng = np.random.default_rng(1)
    for _ in range(20):
        q, _ = _state(rng, model, deflection=0.05)
        M = model.mass_matrix(q)
        np.testing.assert_allclose(M, M.T, rtol=0, atol=1e-13 * np.abs(M).max())
        assert np.linalg.eigvalsh(M).min() > 0.0


def _christoffel_check(model, rng, count=4):
    N = model.n_q
    qs = ca.MX.sym("q", N)
    dM = ca.Function("dM", [qs], [ca.jacobian(ca.vec(model.functions["M"](qs)), qs)])
    for _ in range(count):
        q, qd = _state(rng, model, deflection=0.03)
        D = np.array(dM(q)).reshape(N, N, N, order="F")  # D[i, j, k] = dM_ij / dq_k
        gamma = 0.5 * (D + D.transpose(0, 2, 1) - D.transpose(2, 1, 0))  # Gamma_ijk
        C = gamma @ qd
        M_dot = D @ qd
        S = M_dot - 2 * C
        np.testing.assert_allclose(S, -S.T, atol=1e-11 * np.abs(M_dot).max())
        c = model.coriolis(q, qd)
        np.testing.assert_allclose(c, C @ qd, rtol=1e-9, atol=1e-11 * np.abs(C @ qd).max())


@pytest.mark.parametrize("modes", ["frozen", "scheduled"])
def test_christoffel_consistency(model_path, modes):
    model = build_amm(_general_arm(model_path), 2, modes=modes)
    _christoffel_check(model, np.random.default_rng(2))


def test_coriolis_forms_agree(model_path):
    arm = _general_arm(model_path)
    bodies, lagrange = build_amm(arm, 2), build_amm(arm, 2, coriolis="lagrange")
    rng = np.random.default_rng(3)
    for _ in range(5):
        q, qd = _state(rng, bodies, deflection=0.05)
        ref = lagrange.coriolis(q, qd)
        np.testing.assert_allclose(
            bodies.coriolis(q, qd), ref, rtol=1e-10, atol=1e-12 * np.abs(ref).max()
        )


@pytest.mark.parametrize("solver", ["ldl", "qr"])
def test_forward_dynamics_solves_equations_of_motion(model_path, solver):
    arm = _general_arm(model_path)
    arm = dataclasses.replace(
        arm,
        links=tuple(dataclasses.replace(l, damping_ratios=(0.02,)) for l in arm.links),
        joints=tuple(dataclasses.replace(j, friction=0.3) for j in arm.joints),
    )
    model = build_amm(arm, 2, solver=solver)
    K = np.array(model.functions["K"]()["K"])
    D = np.array(model.functions["D"]()["D"])
    rng = np.random.default_rng(4)
    for _ in range(5):
        q, qd = _state(rng, model)
        tau = rng.normal(size=3) * 10
        qdd = model.forward_dynamics(q, qd, tau)
        lhs = model.mass_matrix(q) @ qdd + model.coriolis(q, qd) + model.gravity(q) + K @ q + D @ qd
        np.testing.assert_allclose(
            lhs, np.concatenate([tau, np.zeros(model.n_q - 3)]), atol=1e-9 * np.abs(K @ q).max()
        )


@pytest.mark.parametrize("modes", ["frozen", "scheduled"])
def test_jacobian_of_f_matches_central_differences(model_path, modes):
    model = build_amm(_general_arm(model_path), 2, modes=modes)
    f = model.functions["f"]
    xs, us = ca.MX.sym("x", model.n_x), ca.MX.sym("u", model.n_u)
    jac = ca.Function("jac_f", [xs, us], [ca.jacobian(f(xs, us), ca.vertcat(xs, us))])
    rng = np.random.default_rng(5)
    for _ in range(3):
        q, qd = _state(rng, model)
        z = np.concatenate([q, qd, rng.normal(size=model.n_u)])
        J = np.array(jac(z[: model.n_x], z[model.n_x :]))
        J_fd = np.zeros_like(J)
        for k in range(z.size):
            h = 1e-5 * max(1.0, abs(z[k]))
            zp, zm = z.copy(), z.copy()
            zp[k] += h
            zm[k] -= h
            fp = np.array(f(zp[: model.n_x], zp[model.n_x :])).ravel()
            fm = np.array(f(zm[: model.n_x], zm[model.n_x :])).ravel()
            J_fd[:, k] = (fp - fm) / (2 * h)
        col_scale = np.abs(J).max(axis=0, keepdims=True) + 1e-3 * np.abs(J).max()
        assert np.max(np.abs(J_fd - J) / col_scale) < 1e-6


def _integrate_energy(model, x0, t_end=0.3, samples=61):
    f = model.functions["f"]
    u = np.zeros(model.n_u)
    sol = solve_ivp(
        lambda t, x: np.array(f(x, u)).ravel(),
        (0.0, t_end),
        x0,
        method="DOP853",
        rtol=1e-11,
        atol=1e-12,
        t_eval=np.linspace(0.0, t_end, samples),
    )
    assert sol.success, sol.message
    N = model.n_q
    parts = np.array(
        [[float(v) for v in model.functions["energies"](x[:N], x[N:])] for x in sol.y.T]
    )
    return parts


@pytest.mark.parametrize("modes", ["frozen", "scheduled"])
def test_energy_conserved_without_damping(model_path, modes):
    model = build_amm(_arm(model_path), 2, modes=modes)
    rng = np.random.default_rng(6)
    q, qd = _state(rng, model, deflection=0.01, rate=1.5)
    parts = _integrate_energy(model, np.concatenate([q, qd]))
    total = parts.sum(axis=1)
    scale = parts[:, 0].max() + parts[:, 1].max() + np.ptp(parts[:, 2])
    assert np.ptp(parts[:, 1]) > 0.1 * parts[:, 1].max()  # energy really moved between forms
    assert np.max(np.abs(total - total[0])) < 1e-6 * scale


def test_energy_decreases_with_damping(model_path):
    arm = _arm(model_path)
    arm = dataclasses.replace(
        arm,
        links=tuple(dataclasses.replace(l, damping_ratios=(0.01,)) for l in arm.links),
        joints=tuple(dataclasses.replace(j, friction=0.5) for j in arm.joints),
    )
    model = build_amm(arm, 2)
    rng = np.random.default_rng(7)
    q, qd = _state(rng, model, deflection=0.01, rate=1.5)
    total = _integrate_energy(model, np.concatenate([q, qd]), samples=301).sum(axis=1)
    steps = np.diff(total)
    assert np.all(steps <= 1e-9 * abs(total[0]))
    assert total[-1] < total[0] - 1e-3 * abs(total[0] - total.min() + 1.0)


def test_output_functions_consistent(model_path):
    # Subedi's kinematics as printed (Eqs 1-9); the axial shortening: test_amm_shortening.py
    arm = dataclasses.replace(_general_arm(model_path), axial_shortening=False)
    model = build_amm(arm, 2)
    rng = np.random.default_rng(8)
    modes = [link_modes(arm, np.asarray(arm.configuration), i, 2) for i in range(3)]
    for _ in range(3):
        q, qd = _state(rng, model, deflection=0.02)
        hubs = np.array(model.functions["hubs"](q))
        p, v = (np.array(a).ravel() for a in model.functions["tip"](q, qd))
        np.testing.assert_allclose(hubs[:, -1], p, atol=1e-14)
        np.testing.assert_allclose(hubs[:, 0], [0.0, 0.0], atol=0)
        h = 1e-6
        pp = np.array(model.functions["tip"](q + h * qd, qd)[0]).ravel()
        pm = np.array(model.functions["tip"](q - h * qd, qd)[0]).ravel()
        np.testing.assert_allclose(v, (pp - pm) / (2 * h), rtol=1e-6, atol=1e-8)
        w, dw = (np.array(a).ravel() for a in model.functions["deflection"](q))
        qf = q[3:].reshape(3, 2)
        np.testing.assert_allclose(
            w, [modes[i].tip_deflection @ qf[i] for i in range(3)], rtol=1e-12, atol=1e-15
        )
        np.testing.assert_allclose(
            dw, [modes[i].tip_slope @ qf[i] for i in range(3)], rtol=1e-12, atol=1e-15
        )
        # each hub sits at the previous one plus the deflected tip vector of the link (Eqs 4, 7)
        theta, frame = 0.0, np.eye(2)
        expected = [np.zeros(2)]
        for i in range(3):
            theta += q[i]
            rot = frame @ np.array(
                [[math.cos(q[i]), -math.sin(q[i])], [math.sin(q[i]), math.cos(q[i])]]
            )
            expected.append(expected[-1] + rot @ np.array([arm.links[i].length, w[i]]))
            frame = rot @ np.array([[1.0, -dw[i]], [dw[i], 1.0]])
        np.testing.assert_allclose(hubs, np.column_stack(expected), atol=1e-13)


def _energies_by_quadrature(arm, modes, q, qd, points=24):
    """T and U_g of the arm from the continuous kinematics (Eqs 1-9, 42-49), by Gauss quadrature
    over each link with the mode shapes, velocities by central differences along qd.

    ``modes``: one set of modes per link, or a function of the joint angles giving them
    (shapes that move with the configuration)."""
    n = arm.n_links
    modes_at = modes if callable(modes) else (lambda q_r: modes)
    offsets = np.cumsum([n] + [m.n_modes for m in modes_at(q[:n])])
    xg, wg = np.polynomial.legendre.leggauss(points)
    g = np.asarray(arm.gravity, dtype=float)

    def bodies(q):
        r, frame, angle = np.zeros(2), np.eye(2), 0.0
        out = []  # (kind, mass or rho-weights, positions, angle, inertia)
        for i, (link, joint, md) in enumerate(zip(arm.links, arm.joints, modes_at(q[:n]))):
            qf = q[offsets[i] : offsets[i + 1]]
            W = frame @ np.array(
                [[math.cos(q[i]), -math.sin(q[i])], [math.sin(q[i]), math.cos(q[i])]]
            )
            angle = angle + q[i]
            out.append((joint.hub_mass, r.copy(), angle, joint.hub_inertia))
            x = 0.5 * link.length * (xg + 1)
            pts = r[:, None] + W @ np.vstack([x, qf @ md.shape(x)])
            out.append((0.5 * link.length * wg * link.mass_per_length, pts, None, 0.0))
            w_e, dw_e = qf @ md.shape(link.length), qf @ md.shape(link.length, 1)
            r = r + W @ np.array([link.length, w_e])
            frame = W @ np.array([[1.0, -dw_e], [dw_e, 1.0]])
            angle = angle + dw_e
        out.append((arm.payload.mass, r, angle, arm.payload.effective_inertia))
        return out

    h = 1e-6
    plus, minus, here = bodies(q + h * qd), bodies(q - h * qd), bodies(q)
    T = U = 0.0
    for (m, p1, a1, J), (_, p0, a0, _), (_, p, _, _) in zip(plus, minus, here):
        v = (p1 - p0) / (2 * h)
        T += 0.5 * np.sum(m * v**2)
        U -= np.sum(m * (g @ p))
        if a1 is not None:
            T += 0.5 * J * ((a1 - a0) / (2 * h)) ** 2
    return T, U


def test_energies_match_quadrature_of_the_continuum(model_path):
    # the continuum of Eqs 1-9 (no axial shortening; that one: test_amm_shortening.py)
    arm = dataclasses.replace(_general_arm(model_path, slender=True), axial_shortening=False)
    model = build_amm(arm, 3)
    modes = [link_modes(arm, np.asarray(arm.configuration), i, 3) for i in range(3)]
    rng = np.random.default_rng(11)
    for _ in range(4):
        q, qd = _state(rng, model, deflection=0.05)
        T_ref, U_ref = _energies_by_quadrature(arm, modes, q, qd)
        E_kin, E_el, E_grav = (float(v) for v in model.functions["energies"](q, qd))
        np.testing.assert_allclose(E_kin, T_ref, rtol=1e-8)
        np.testing.assert_allclose(E_grav, U_ref, rtol=1e-10, atol=1e-10 * abs(U_ref))
        np.testing.assert_allclose(E_kin, 0.5 * qd @ model.mass_matrix(q) @ qd, rtol=1e-12)
        k = np.concatenate([[m.stiffness for m in modes]]).ravel()
        np.testing.assert_allclose(E_el, 0.5 * np.sum(k * q[3:] ** 2), rtol=1e-12)
        # gravity vector: central differences of the independent U_g
        grad = np.zeros(model.n_q)
        for j in range(model.n_q):
            e = np.zeros(model.n_q)
            e[j] = 1e-6
            grad[j] = (
                _energies_by_quadrature(arm, modes, q + e, qd)[1]
                - _energies_by_quadrature(arm, modes, q - e, qd)[1]
            ) / 2e-6
        np.testing.assert_allclose(
            model.gravity(q), grad, rtol=1e-6, atol=1e-6 * np.abs(grad).max()
        )


class _SignedModes:
    """Exact clamped-mass modes with the signs of the lookup's modes (for comparisons)."""

    def __init__(self, modes, signs):
        self.modes, self.signs, self.n_modes = modes, np.asarray(signs, dtype=float), modes.n_modes

    def shape(self, x, derivative=0):
        return self.signs.reshape((-1,) + (1,) * np.ndim(x)) * self.modes.shape(x, derivative)


def _lookups(arm, n_modes=2):
    from flexctrl.modal.lookup import modal_lookup

    return [modal_lookup(arm, i, n_modes) for i in range(arm.n_links)]


def _exact_modes_like_lookup(arm, q_r, lookups):
    out = []
    for i, lookup in enumerate(lookups):
        exact = link_modes(arm, q_r, i, lookup.n_modes)
        looked = lookup.evaluate(q_r)
        out.append(_SignedModes(exact, np.sign(looked["tip_deflection"] * exact.tip_deflection)))
    return out


def _sign_matrix(arm, q_r, lookups):
    signs = np.concatenate([m.signs for m in _exact_modes_like_lookup(arm, q_r, lookups)])
    return np.diag(np.concatenate([np.ones(arm.n_links), signs]))


def test_scheduled_mass_matrix_equals_frozen_at_zero_deflection(model_path):
    """At a pose on the table grid, with no deflection, M of the scheduled model equals that of
    the model frozen there (the shape-rate terms are proportional to the deflection)."""
    arm = _arm(model_path)
    q_ref = np.radians([20.0, 30.0, -40.0])
    frozen, scheduled = build_amm(arm, 2, reference_q=q_ref), build_amm(arm, 2, modes="scheduled")
    S = _sign_matrix(arm, q_ref, _lookups(arm))  # lookup modes may be sign-flipped
    q = np.concatenate([q_ref, np.zeros(6)])
    np.testing.assert_allclose(
        scheduled.mass_matrix(q), S @ frozen.mass_matrix(q) @ S, rtol=1e-7, atol=1e-9
    )


def test_scheduled_inertial_load_equals_frozen_at_rest_deflection(model_path):
    """Undeformed and not vibrating (q_f = qd_f = 0) but swinging, the scheduled model must load
    its modes exactly as the model frozen at the current configuration does: the inertial load
    int rho phi . a does not care how the shapes will change.  Moving shapes enter only through
    terms proportional to the deflection.  A model that forms T from frozen-shape velocities
    fails this by a force (dv/dt)(n . rdot) + (dw/dt) alpha-dot on the modes (measured with
    that model: 117 % and 171 % of the largest elastic acceleration at these two poses)."""
    arm = _arm(model_path)
    scheduled, lookups = build_amm(arm, 2, modes="scheduled"), _lookups(arm)
    rng = np.random.default_rng(21)
    for q_deg in ([20.0, 30.0, -40.0], [-35.0, 77.0, 123.0]):  # on and off the 10-degree grid
        q_r = np.radians(q_deg)
        frozen = build_amm(arm, 2, reference_q=q_r)
        S = _sign_matrix(arm, q_r, lookups)
        q = np.concatenate([q_r, np.zeros(6)])
        qd = np.concatenate([rng.normal(size=3) * 2.0, np.zeros(6)])
        tau = rng.normal(size=3) * 20.0
        ref = S @ frozen.forward_dynamics(q, qd, tau)
        got = scheduled.forward_dynamics(q, qd, tau)
        np.testing.assert_allclose(got, ref, rtol=0, atol=2e-5 * np.abs(ref[3:]).max())


def test_scheduled_kinetic_energy_matches_moving_shapes_quadrature(model_path):
    """T of the scheduled model against T of the continuum whose deflection is
    sum phi_j(x; q_r) q_fj with the exact shapes at each configuration (velocities by
    central differences, so the shapes' change is in them).  The part of T that the
    shapes' motion adds must be reproduced, not just the rest."""
    arm = dataclasses.replace(_arm(model_path), axial_shortening=False)  # the continuum of Eqs 1-9
    scheduled, lookups = build_amm(arm, 2, modes="scheduled"), _lookups(arm)
    rng = np.random.default_rng(22)
    for q_deg in ([20.0, 30.0, -40.0], [-35.0, 77.0, 123.0]):  # on and off the 10-degree grid
        q_r = np.radians(q_deg)
        q = np.concatenate([q_r, 0.05 * rng.normal(size=6)])
        qd = np.concatenate([rng.normal(size=3) * 2.0, rng.normal(size=6) * 0.2])
        T_model = float(scheduled.functions["energies"](q, qd)[0])
        T_ref = _energies_by_quadrature(
            arm, lambda q_now: _exact_modes_like_lookup(arm, q_now, lookups), q, qd
        )[0]
        T_still = _energies_by_quadrature(arm, _exact_modes_like_lookup(arm, q_r, lookups), q, qd)[
            0
        ]  # shapes held still
        assert abs(T_ref - T_still) > 2e-5 * T_ref  # the shapes' motion is really in the reference
        assert abs(T_model - T_ref) < 0.01 * abs(T_ref - T_still)
        assert np.linalg.eigvalsh(scheduled.mass_matrix(q)).min() > 0.0


def test_scheduled_equals_frozen_where_modes_agree(model_path):
    """At the reference configuration (a grid point of the table) both see the same modes."""
    arm = _arm(model_path)
    frozen, scheduled = build_amm(arm, 2), build_amm(arm, 2, modes="scheduled")
    np.testing.assert_allclose(
        scheduled.info["locked_frequencies_rad_s"],
        frozen.info["locked_frequencies_rad_s"],
        rtol=1e-8,
    )
    np.testing.assert_allclose(scheduled.omega_max, frozen.omega_max, rtol=1e-8)
    rng = np.random.default_rng(9)
    for _ in range(3):  # the rigid block does not depend on the modes
        q, _ = _state(rng, frozen)
        q[3:] = 0.0
        np.testing.assert_allclose(
            scheduled.mass_matrix(q)[:3, :3], frozen.mass_matrix(q)[:3, :3], rtol=1e-12
        )
    K_s = np.array(scheduled.functions["K"](np.zeros(9)))
    np.testing.assert_allclose(
        np.diag(K_s), np.diag(np.array(frozen.functions["K"]()["K"])), rtol=1e-8
    )


def test_build_model_interface(model_path):
    rigid = load_model(model_path, fidelity="rigid")
    assert rigid.coordinate_names == ("q1", "q2", "q3") and str(rigid.fidelity) == "rigid"
    amm0 = load_model(model_path, fidelity="amm:0")
    q = np.array([0.3, -0.5, 1.1])
    np.testing.assert_allclose(rigid.mass_matrix(q), amm0.mass_matrix(q), rtol=1e-14)
    model = flexctrl.load_model(model_path, payload=0.0, fidelity="amm:2")
    assert model.coordinate_names == (
        "q1",
        "q2",
        "q3",
        "qf11",
        "qf12",
        "qf21",
        "qf22",
        "qf31",
        "qf32",
    )
    assert model.spec.payload.mass == 0.0 and model.n_x == 18 and model.n_u == 3
    assert len(model.info["link_frequencies_rad_s"]) == 3 and model.omega_max > 0
    per_file = load_model(model_path, fidelity=None, overrides=["links[1].n_modes=1"])
    assert per_file.info["n_modes"] == [1, 2, 2]
    fem = load_model(model_path, fidelity="fem:2")  # the same file builds as finite elements
    assert (
        str(fem.fidelity) == "fem:2"
        and fem.n_u == 3
        and fem.coordinate_names[:3] == ("q1", "q2", "q3")
    )
    with pytest.raises(ModelFamilyUnavailable, match="assumed modes only") as err:
        load_model(model_path, fidelity="fem:2", modes="scheduled")
    assert isinstance(err.value, FlexctrlError) and isinstance(err.value, NotImplementedError)
    with pytest.raises(SpecError, match="allowed"):
        build_model(rigid.spec, "amm:9")
    with pytest.raises(SpecError, match="'frozen', 'scheduled'"):
        build_model(rigid.spec, "amm:1", modes="schedule")
    with pytest.raises(SpecError, match="fidelity amm has no mode count"):
        build_model(rigid.spec, Fidelity("amm"))
    with pytest.raises(SpecError, match="fidelity fem has no element count"):
        build_model(rigid.spec, Fidelity("fem"))


def test_the_model_name_says_only_what_differs_from_the_default_kinematics(model_path):
    """The name carries the modes and the options off their defaults, never the default rotation."""
    arm = load_arm(model_path)
    names = {
        "plain": build_amm(arm, 1).name,
        "shortening": build_amm(arm, 1, axial_shortening=True).name,
        "exact": build_amm(arm, 1, tip_rotation="exact").name,
        "shortening_linearized": build_amm(
            arm, 1, axial_shortening=True, tip_rotation="linearized"
        ).name,
    }
    assert names == {
        "plain": "subedi3link amm 1/1/1 frozen no-shortening",
        "shortening": "subedi3link amm 1/1/1 frozen",
        "exact": "subedi3link amm 1/1/1 frozen no-shortening exact-rotation",
        "shortening_linearized": "subedi3link amm 1/1/1 frozen linearized-rotation",
    }
