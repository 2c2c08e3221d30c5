"""Floating-frame finite-element arm (flexctrl.dynamics.fem.fem_arm) and the per-link FE modal
check.

Reference values are independent solutions or limits, never stored output: the
closed-form clamped-mass frequencies, mesh refinement (h^4 eigenvalue
convergence of Hermite elements), the assumed-modes model as a second Ritz
basis, the rigid arm, Lagrangian energy conservation and Southwell's
centrifugal-stiffening coefficient.
"""

from __future__ import annotations

import dataclasses
import json
import math

import casadi as ca
import numpy as np
import pytest
import scipy.linalg
from model_checks import rotating_frequency
from scipy.integrate import solve_ivp
from support import MODEL

from flexctrl.dynamics.fem.fem_arm import (
    build_fem_model,
    fem_coordinate_names,
    generalized_frequencies,
    locked_matrices,
    relax_axial,
)
from flexctrl.dynamics.fem.newmark import simulate_model_newmark
from flexctrl.dynamics.fem.newmark_dae import DAEProblem, simulate
from flexctrl.errors import SpecError
from flexctrl.modal.arm_modes import link_modes
from flexctrl.modal.fem_modes import link_frequencies_fem
from flexctrl.modal.paper_data import SUBEDI_TABLE3_HZ, SUBEDI_TABLE3_ROUNDING_HZ
from flexctrl.spec.arm import load_arm

CONFIGS = [(0.0, 0.0, 0.0), (0.0, 90.0, 0.0), (0.0, 45.0, -90.0)]


@pytest.fixture(scope="module")
def arm():
    return load_arm(MODEL)


@pytest.fixture(scope="module")
def fem4(arm):
    return build_fem_model(arm, 4)


def no_gravity(arm):
    return dataclasses.replace(arm, gravity=(0.0, 0.0))


def stiff_axial(arm, factor=1e4):
    return dataclasses.replace(
        arm, links=tuple(dataclasses.replace(l, EA=l.axial_stiffness() * factor) for l in arm.links)
    )


# -- 1. per-link clamped-mass check ----------------------------------------------------------------
@pytest.mark.parametrize("payload", [0.0, 2.0])
def test_link_frequencies_fem_converge_to_clamped_mass_modes(arm, payload):
    a = arm.with_payload(payload)
    q = np.zeros(3)
    for link in range(3):
        exact = link_modes(a, q, link, 2).frequency_hz
        errors = [link_frequencies_fem(a, q, link, 2, N) - exact for N in (2, 4, 8, 16)]
        second = [e[1] for e in errors]  # first modes reach rounding (~1e-7 Hz) early
        assert all(e > 0 for e in second) and all(a_ > b_ for a_, b_ in zip(second, second[1:]))
        assert 3.5 < math.log2(second[1] / second[2]) < 4.5  # h^4 in frequency
        f16 = link_frequencies_fem(a, q, link, 2, 16)
        assert np.all(np.abs(f16 - exact) < 1e-3)  # Hz
        np.testing.assert_allclose(
            f16, SUBEDI_TABLE3_HZ[payload][link], atol=SUBEDI_TABLE3_ROUNDING_HZ + 0.01
        )


def test_link_frequencies_fem_validates_its_arguments(arm):
    with pytest.raises(SpecError, match="n_modes"):
        link_frequencies_fem(arm, np.zeros(3), 0, 5, 2)
    with pytest.raises(SpecError, match="n_elements"):
        link_frequencies_fem(arm, np.zeros(3), 0, 2, 0)
    with pytest.raises(SpecError, match="link"):
        link_frequencies_fem(arm, np.zeros(3), 3, 2, 4)
    assert link_frequencies_fem(arm, np.zeros(3), 0, 0, 4).shape == (0,)


def test_modes_command_with_fem_fidelity(capsys):
    from flexctrl.cli import main

    assert main(["modes", str(MODEL), "--fidelity", "fem:16", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    f = [entry["frequencies_hz"] for entry in out["links"]]
    np.testing.assert_allclose(f, SUBEDI_TABLE3_HZ[2.0], atol=SUBEDI_TABLE3_ROUNDING_HZ + 0.01)


# -- 2. the model interface ------------------------------------------------------------------------
def test_model_interface(fem4):
    m = fem4
    assert str(m.fidelity) == "fem:4" and m.n_joints == 3
    assert m.coordinate_names == fem_coordinate_names(3, 4)
    assert m.coordinate_names[:6] == ("q1", "q2", "q3", "w1_1", "th1_1", "w1_2")
    assert m.n_q == 3 + 3 * 4 * 3
    assert {"M", "c", "g", "K", "D", "f", "energies", "tip", "hubs", "deflection"} <= set(
        m.functions
    )
    rng = np.random.default_rng(3)
    q = np.r_[rng.uniform(-1, 1, 3), 1e-3 * rng.normal(size=m.n_q - 3)]
    qd = rng.normal(size=m.n_q)
    hubs = np.array(m.functions["hubs"](q))
    p, v = (np.array(a).ravel() for a in m.functions["tip"](q, qd))
    assert hubs.shape == (2, 4)
    np.testing.assert_allclose(hubs[:, -1], p)
    np.testing.assert_allclose(hubs[:, 0], 0.0)
    h = 1e-7  # tip velocity is the time derivative of the tip position
    p2 = np.array(m.functions["tip"](q + h * qd, qd)[0]).ravel()
    np.testing.assert_allclose((p2 - p) / h, v, rtol=1e-5, atol=1e-6)
    w, dw = (np.array(a).ravel() for a in m.functions["deflection"](q))
    names = m.coordinate_names
    np.testing.assert_array_equal(w, [q[names.index(f"w{i}_4")] for i in (1, 2, 3)])
    np.testing.assert_array_equal(dw, [q[names.index(f"th{i}_4")] for i in (1, 2, 3)])
    assert m.omega_max == pytest.approx(max(m.info["locked_frequencies_rad_s"]))
    assert m.info["family"] == "fem" and m.info["axial_shortening"] is True


def test_build_rejects_what_it_cannot_model(arm):
    with pytest.raises(SpecError, match="n_elements"):
        build_fem_model(arm, 0)
    with pytest.raises(SpecError, match="n_elements"):
        build_fem_model(arm, 65)
    prismatic = dataclasses.replace(
        arm, joints=(dataclasses.replace(arm.joints[0], type="prismatic"),) + arm.joints[1:]
    )
    with pytest.raises(SpecError, match="joints\\[1\\].type"):
        build_fem_model(prismatic, 2)
    no_ea = dataclasses.replace(
        arm, links=(dataclasses.replace(arm.links[0], section=None, EA=None),) + arm.links[1:]
    )
    with pytest.raises(SpecError, match="EA"):
        build_fem_model(no_ea, 2)


# -- 3. mass matrix and dynamics -------------------------------------------------------------------
def smooth_state(m, rng, slope):
    """Joint angles anywhere, links bent like cantilevers with tip slopes up to ``slope`` rad."""
    N = 4
    q = np.zeros(m.n_q)
    q[:3] = rng.uniform(-math.pi, math.pi, 3)
    x = np.arange(1, N + 1) / N * 1.5
    for i in range(3):
        s = rng.uniform(-slope, slope)
        base = 3 + 3 * N * i
        q[base : base + 2 * N : 2] = s * x**2 / 3.0
        q[base + 1 : base + 2 * N : 2] = s * x / 1.5
    return relax_axial(m, q)


def test_mass_matrix_symmetric_positive_definite_and_dynamics_consistent(fem4):
    m = fem4
    rng = np.random.default_rng(0)
    K = np.array(m.functions["K"]()["K"])
    D = np.array(m.functions["D"]()["D"])
    for slope in (0.01, 0.1, 0.3):
        q = smooth_state(m, rng, slope)
        qd = rng.normal(size=m.n_q)
        u = rng.normal(size=3)
        M = m.mass_matrix(q)
        np.testing.assert_allclose(M, M.T, atol=1e-13)
        assert np.linalg.eigvalsh(M).min() > 0.0
        assert m.energies(q, qd)["E_kin"] == pytest.approx(0.5 * qd @ M @ qd, rel=1e-12)
        # c = Mdot qd - 1/2 d(qd^T M qd)/dq, with derivatives by central differences of M
        e = 1e-6
        Mdot = (m.mass_matrix(q + e * qd) - m.mass_matrix(q - e * qd)) / (2 * e)
        grad = np.array(
            [
                (qd @ m.mass_matrix(q + e * ek) @ qd - qd @ m.mass_matrix(q - e * ek) @ qd)
                / (2 * e)
                for ek in np.eye(m.n_q)
            ]
        )
        np.testing.assert_allclose(m.coriolis(q, qd), Mdot @ qd - 0.5 * grad, rtol=1e-6, atol=1e-6)
        rhs = np.r_[u, np.zeros(m.n_q - 3)] - m.coriolis(q, qd) - m.gravity(q) - K @ q - D @ qd
        np.testing.assert_allclose(
            m.forward_dynamics(q, qd, u),
            np.linalg.solve(M, rhs),
            rtol=1e-9,
            atol=1e-9 * np.abs(rhs).max(),
        )


def test_rigid_limit_matches_the_rigid_arm(arm):
    from flexctrl.dynamics.build import build_model

    a = arm.with_payload(2.0)
    m = build_fem_model(a, 2)
    rigid = build_model(a, "rigid")
    rng = np.random.default_rng(1)
    for _ in range(3):  # straight links: joint-space blocks are the rigid arm's, whatever EI
        qr, qdr = rng.uniform(-3, 3, 3), rng.normal(size=3)
        q, qd = np.r_[qr, np.zeros(m.n_q - 3)], np.r_[qdr, np.zeros(m.n_q - 3)]
        np.testing.assert_allclose(m.mass_matrix(q)[:3, :3], rigid.mass_matrix(qr), rtol=1e-13)
        np.testing.assert_allclose(m.gravity(q)[:3], rigid.gravity(qr), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(
            m.coriolis(q, qd)[:3], rigid.coriolis(qr, qdr), rtol=1e-12, atol=1e-12
        )
    # stiff links move like the rigid arm: 0.3 s of the bang-bang torque at joint 3, no gravity
    stiff = no_gravity(
        dataclasses.replace(a, links=tuple(dataclasses.replace(l, EI=l.EI * 1e4) for l in a.links))
    )
    fem, rig = build_fem_model(stiff, 2), build_model(no_gravity(a), "rigid")

    # a smooth torque: Newmark's endpoint sampling of a bang-bang step would shift its impulse
    def torque(t):
        return np.array([0.0, 0.0, 50.0 * math.sin(10 * math.pi * t) if t < 0.2 else 0.0])

    res = simulate_model_newmark(fem, np.zeros(fem.n_x), 0.3, 1e-3, torque=torque)
    sol = solve_ivp(
        lambda t, y: np.r_[y[3:], rig.forward_dynamics(y[:3], y[3:], torque(t))],
        (0, 0.3),
        np.zeros(6),
        t_eval=res.t,
        rtol=1e-10,
        atol=1e-12,
        max_step=1e-3,
    )
    assert np.abs(sol.y[2]).max() > 0.1  # joint 3 swings
    np.testing.assert_allclose(res.q[:, :3], sol.y[:3].T, atol=2e-4)


# -- 4. locked-joint frequencies ------------------------------------------------------------------
@pytest.mark.parametrize("payload", [0.0, 2.0])
@pytest.mark.parametrize("q_deg", CONFIGS)
def test_locked_frequencies_converge_from_above_at_fourth_order(arm, payload, q_deg):
    a = arm.with_payload(payload)
    lam = {
        N: generalized_frequencies(*locked_matrices(a, N, np.radians(q_deg))[::-1])[:6] ** 2
        for N in (2, 4, 8, 16, 32)
    }
    for N in (2, 4, 8, 16):  # nested meshes, consistent mass: monotone from above
        assert np.all(lam[N] >= lam[2 * N] * (1 - 1e-10))
    err = {N: (lam[N] - lam[32]) / lam[32] for N in (4, 8)}
    resolved = err[8] > 1e-6  # above rounding (~1e-9) by a margin; the higher modes always are
    assert resolved[3:].all()
    order = np.log2(err[4][resolved] / err[8][resolved])
    assert np.all((order > 3.6) & (order < 4.4)), order


@pytest.mark.parametrize("q_deg", [(0.0, 90.0, 0.0), (0.0, 45.0, -90.0)])
def test_locked_frequencies_agree_with_assumed_modes(arm, q_deg):
    """AMM-4 is a Ritz basis of the same structure (clamped-mass modes of each link, coupled):
    with axially rigid links it must sit just above FEM-16; the file's EA lowers FEM slightly."""
    from flexctrl.dynamics.fem.locked_spectrum import locked_amm_hz, locked_fem_hz

    a = arm.with_payload(2.0)
    amm4, amm2 = locked_amm_hz(a, 4, q_deg), locked_amm_hz(a, 2, q_deg)
    rigid_axial = locked_fem_hz(stiff_axial(a), 16, q_deg)
    rel4 = (amm4 - rigid_axial) / rigid_axial
    assert np.all(rel4 > -1e-6) and np.all(rel4 < 5e-4), rel4
    fem = locked_fem_hz(a, 16, q_deg)
    assert np.all(np.abs(amm4[:3] - fem[:3]) / fem[:3] < 1e-3)  # axial compliance: < 0.1 %
    assert np.all(np.abs(amm4[3:] - fem[3:]) / fem[3:] < 5e-3)
    # two modes per link: the first mode of each link is right, the second ones are too stiff
    assert np.all(np.abs(amm2[:3] - fem[:3]) / fem[:3] < 1e-3)
    assert np.all(amm2[3:] > fem[3:] * 1.005)


# -- 5. energy -------------------------------------------------------------------------------------
def test_free_motion_conserves_energy(arm):
    """No damping, no torque, gravity on, joints free: T + U is a first integral of the model."""
    a = arm.with_payload(2.0)
    m = build_fem_model(a, 2)
    rng = np.random.default_rng(5)
    q0 = relax_axial(m, np.r_[np.radians([10.0, 40.0, -60.0]), 2e-3 * rng.normal(size=m.n_q - 3)])
    qd0 = np.r_[0.5, -0.3, 1.0, np.zeros(m.n_q - 3)]
    f = m.functions["f"]
    sol = solve_ivp(
        lambda t, x: np.asarray(f(x, np.zeros(3))).ravel(),
        (0.0, 0.05),
        np.r_[q0, qd0],
        method="DOP853",
        rtol=1e-11,
        atol=1e-13,
    )
    E = np.array([m.energies(x[: m.n_q], x[m.n_q :])["E_total"] for x in sol.y.T])
    assert np.ptp(E) < 1e-8 * np.abs(E).max()


def test_locked_free_vibration_energy_with_newmark(arm):
    """Trapezoidal Newmark conserves the energy of linear systems exactly; the locked arm is
    linear up to its geometric nonlinearity, where the rule's energy error is second order in dt."""
    a = no_gravity(arm)
    m = build_fem_model(a, 4)
    q_r = np.radians([0.0, 45.0, -90.0])
    M0, K0 = locked_matrices(a, 4, q_r)
    lam, V = scipy.linalg.eigh(K0, M0)
    tip = m.coordinate_names.index("w3_4") - 3
    shape = 0.01 * V[:, 0] / V[tip, 0]  # first locked mode, 1 cm at the arm's tip
    q0 = relax_axial(m, np.r_[q_r, shape])
    drift = {}
    for dt in (1e-3, 5e-4):
        res = simulate_model_newmark(m, np.r_[q0, np.zeros(m.n_q)], 0.3, dt, locked=q_r)
        E = np.array([m.energies(q, qd)["E_total"] for q, qd in zip(res.q, res.qd)])
        drift[dt] = np.ptp(E) / E[0]
        assert (
            res.phi_violation.max() < 1e-12 and np.abs(res.qd[:, :3]).max() < 1e-12
        )  # joints held
        assert np.abs(res.q[:, 3 + tip]).max() == pytest.approx(0.01, rel=0.02)
    assert drift[1e-3] < 1e-5
    assert drift[1e-3] / drift[5e-4] > 3.0  # second order
    # the linearised locked system: energy exact to rounding
    n = m.n_q - 3
    lin = DAEProblem(
        n_q=n,
        n_c=0,
        mass=lambda q, t: M0,
        force=lambda q, qd, t: -K0 @ q,
        phi=lambda q, t: np.zeros(0),
        phi_q=lambda q, t: np.zeros((0, n)),
        phi_t=lambda q, t: np.zeros(0),
        h=lambda q, qd, t: np.zeros(0),
        force_q=lambda q, qd, t: -K0,
        force_qd=lambda q, qd, t: np.zeros((n, n)),
        h_q=lambda q, qd, t: np.zeros((0, n)),
        h_qd=lambda q, qd, t: np.zeros((0, n)),
        linear=True,
    )
    static = np.linalg.solve(K0, np.eye(n)[tip])  # static tip-load shape: every mode excited
    r = simulate(lin, static, np.zeros(n), 0.3, 1e-3)
    El = np.array([0.5 * v @ M0 @ v + 0.5 * x @ K0 @ x for x, v in zip(r.q, r.qd)])
    assert np.ptp(El) < 1e-10 * El[0]


# -- 6. axial shortening ---------------------------------------------------------------------------
@pytest.mark.parametrize("shortening, coefficient", [(True, 0.1933), (False, -1.0)])
def test_axial_shortening_gives_southwell_centrifugal_stiffening(arm, shortening, coefficient):
    """In-plane bending of a spinning cantilever: omega^2 = omega_0^2 + (1.1933 - 1) Omega^2
    (Southwell; the -1 is the frame's softening, the 1.1933 Pan's axial-force term)."""
    one = dataclasses.replace(
        arm.with_payload(0.0),
        links=arm.links[2:],
        configuration=(0.0,),
        gravity=(0.0, 0.0),
        joints=(dataclasses.replace(arm.joints[2], hub_mass=0.0),),
    )
    m = build_fem_model(one, 8, axial_shortening=shortening)
    w0 = rotating_frequency(m, 0.0)
    spin = 0.1 * w0
    w = rotating_frequency(m, spin)
    assert (w**2 - w0**2) / spin**2 == pytest.approx(coefficient, abs=0.006)


def test_axial_shortening_under_gravity(arm):
    """A hanging link with its payload is stiffened by the weight below each section, a standing one
    softened by as much (to first order): d(omega^2) = g int (rho (L - x) + m_t) phi'^2 / m_l for
    the clamped-mass mode phi (Rayleigh, exact to first order). Without the term neither changes."""
    one = dataclasses.replace(
        arm.with_payload(2.0),
        links=arm.links[2:],
        configuration=(0.0,),
        joints=(dataclasses.replace(arm.joints[2], hub_mass=0.0),),
    )

    def lowest(model, angle):  # linearised about the sagging equilibrium, joint clamped
        n = model.n_q
        q = ca.SX.sym("q", n)
        F = (model.functions["g"](q) + ca.mtimes(model.functions["K"]()["K"], q))[1:]
        fun = ca.Function("F", [q], [F, ca.jacobian(F, q)[:, 1:]])
        qf = np.zeros(n - 1)
        for _ in range(30):
            r, J = (np.asarray(v, dtype=float) for v in fun(np.r_[angle, qf]))
            qf -= np.linalg.solve(J, r.ravel())
        _, J = (np.asarray(v, dtype=float) for v in fun(np.r_[angle, qf]))
        M = model.mass_matrix(np.r_[angle, qf])[1:, 1:]
        return generalized_frequencies(0.5 * (J + J.T), M)[0]

    link, L = one.links[0], one.links[0].length
    x = np.linspace(0.0, L, 20001)
    slope = link_modes(one, np.zeros(1), 0, 1).shape(x, 1)[0]
    rayleigh = 9.81 * np.trapezoid((link.mass_per_length * (L - x) + 2.0) * slope**2, x) / link.mass
    on, off = build_fem_model(one, 8), build_fem_model(one, 8, axial_shortening=False)
    down, up = -math.pi / 2, math.pi / 2
    assert (lowest(on, down) ** 2 - lowest(on, up) ** 2) / 2 == pytest.approx(rayleigh, rel=5e-3)
    assert lowest(on, down) > lowest(off, down) > lowest(on, up)
    assert lowest(off, down) == pytest.approx(lowest(off, up), rel=1e-7)


def test_relax_axial_removes_membrane_strain(fem4):
    rng = np.random.default_rng(7)
    q = smooth_state(fem4, rng, 0.05)
    bend = q.copy()
    bend[[k for k, n in enumerate(fem4.coordinate_names) if n.startswith("u")]] = 0.0
    K = np.array(fem4.functions["K"]()["K"])
    e_bending = 0.5 * bend @ K @ bend
    assert fem4.energies(q, np.zeros(fem4.n_q))["E_el"] == pytest.approx(e_bending, rel=1e-9)
    assert (
        fem4.energies(bend, np.zeros(fem4.n_q))["E_el"] > 1.2 * e_bending
    )  # unrelaxed: membrane strain
