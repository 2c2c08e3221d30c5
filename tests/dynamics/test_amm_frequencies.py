"""Locked-joint frequencies of the assumed-modes model against independent beam solutions.

The linearisation of the whole model (``-M df/dq`` at rest, no gravity) with the
joints clamped is compared with

* the clamped-mass eigenvalues of :func:`flexctrl.beam.clamped_mass.clamped_mass_modes`
  (single link: the assumed modes are the exact eigenfunctions, so the model must
  reproduce them to rounding), and
* a fine Hermite finite-element model of the same clamped structure built here from
  :mod:`flexctrl.beam.elements` (straight arm: the locked links form a stepped
  cantilever with the hubs and the payload as point masses with rotary inertia).
  Assumed modes are a Rayleigh-Ritz basis, so their frequencies lie above the exact
  ones and fall monotonically as modes are added.
"""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest
import scipy.linalg

from flexctrl.beam.clamped_mass import clamped_mass_modes
from flexctrl.beam.elements import beam_mass, beam_stiffness
from flexctrl.dynamics.amm import build_amm
from flexctrl.spec.arm import load_arm


def _arm(model_path, n_links):
    arm = load_arm(model_path)
    # slender links: make J_l exactly m L^2/12 so the rigid inertia equals int rho x^2 of the beam
    links = tuple(
        dataclasses.replace(l, inertia=l.mass * l.length**2 / 12) for l in arm.links[:n_links]
    )
    return dataclasses.replace(
        arm,
        links=links,
        joints=arm.joints[:n_links],
        configuration=(0.0,) * n_links,
        gravity=(0.0, 0.0),
    )


def locked_frequencies(model, q_r):
    """Natural frequencies (rad/s) of the model linearised at rest at ``q_r`` with the joints
    clamped."""
    n, N = model.n_joints, model.n_q
    q0 = np.concatenate([q_r, np.zeros(N - n)])
    qs = ca.MX.sym("q", N)
    f = model.functions["f"](ca.vertcat(qs, ca.MX.zeros(N)), ca.MX.zeros(n))[N:]
    A_q = np.array(ca.Function("lin", [qs], [ca.jacobian(f, qs)])(q0))
    M = model.mass_matrix(q0)
    K = -M @ A_q  # tangent stiffness of the whole model
    flex = slice(n, N)
    K_ff, M_ff = K[flex, flex], M[flex, flex]
    return np.sqrt(scipy.linalg.eigh(0.5 * (K_ff + K_ff.T), M_ff, eigvals_only=True))


def stepped_cantilever(arm, elements_per_link=24):
    """Frequencies (rad/s) of the straight, locked arm as one Euler-Bernoulli FE beam."""
    n_nodes = arm.n_links * elements_per_link + 1
    M = np.zeros((2 * n_nodes, 2 * n_nodes))
    K = np.zeros_like(M)
    for i, link in enumerate(arm.links):
        le = link.length / elements_per_link
        me, ke = beam_mass(link.mass_per_length, le), beam_stiffness(link.EI, le)
        for e in range(elements_per_link):
            k = 2 * (i * elements_per_link + e)
            M[k : k + 4, k : k + 4] += me
            K[k : k + 4, k : k + 4] += ke
    for i in range(1, arm.n_links):  # hub i+1 on the tip of link i
        k = 2 * i * elements_per_link
        M[k, k] += arm.joints[i].hub_mass
        M[k + 1, k + 1] += arm.joints[i].hub_inertia
    M[-2, -2] += arm.payload.mass
    M[-1, -1] += arm.payload.effective_inertia
    free = slice(2, None)  # clamp node 0
    return np.sqrt(scipy.linalg.eigh(K[free, free], M[free, free], eigvals_only=True))


@pytest.mark.parametrize("payload", [0.0, 2.0])
def test_single_link_locked_frequencies_are_clamped_mass_frequencies(model_path, payload):
    arm = _arm(model_path, 1).with_payload(payload)
    link = arm.links[0]
    exact = clamped_mass_modes(
        link.length,
        link.mass_per_length,
        link.EI,
        4,
        m_tip=payload,
        J_tip=arm.payload.effective_inertia,
        M_tip=0.0,
    ).omega
    fem = stepped_cantilever(arm, 60)[:4]
    np.testing.assert_allclose(exact, fem, rtol=1e-6)  # the two references agree
    for n_modes in (1, 2, 3, 4):
        for q1 in (0.0, 1.2):  # the joint angle does not matter without gravity
            model = build_amm(arm, n_modes, reference_q=[q1])
            np.testing.assert_allclose(locked_frequencies(model, [q1]), exact[:n_modes], rtol=1e-9)
            # omega_max bounds explicit steps: the higher of the free-joint and locked spectra
            free = max(model.info["free_frequencies_rad_s"])
            assert free >= exact[n_modes - 1] * (
                1 - 1e-9
            )  # freeing the joint stiffens no mode down
            np.testing.assert_allclose(model.omega_max, max(free, exact[n_modes - 1]), rtol=1e-9)


@pytest.mark.parametrize("n_links", [2, 3])
def test_locked_arm_frequencies_converge_from_above(model_path, n_links):
    arm = _arm(model_path, n_links)
    fem = stepped_cantilever(arm)
    previous = None
    errors = []
    for n_modes in (1, 2, 3, 4):
        omega = locked_frequencies(build_amm(arm, n_modes), np.zeros(n_links))
        # Rayleigh-Ritz: every frequency above the exact one (FE with 24 elements per link is
        # converged to ~1e-8 for the lowest 2n modes) ...
        low = min(omega.size, 2 * n_links)
        assert np.all(omega[:low] >= fem[:low] * (1 - 1e-7))
        # ... and non-increasing as the basis grows (the bases are nested)
        if previous is not None:
            assert np.all(omega[: previous.size] <= previous * (1 + 1e-10))
        previous = omega
        errors.append(omega[:n_links] / fem[:n_links] - 1)
    errors = np.array(errors)  # (n_modes, lowest n_links frequencies)
    assert np.all(errors[-1] < 1e-2 * errors[0] + 1e-7)  # converging toward the limit
    assert np.all(errors[-1] < 1e-5)


def test_bent_arm_locked_frequencies_non_increasing(model_path):
    """Away from the straight pose (no simple reference) the Ritz property still holds."""
    arm = _arm(model_path, 3)
    q_r = np.array([0.3, 1.1, -0.8])
    previous, changes = None, []
    for n_modes in (1, 2, 3, 4):
        omega = locked_frequencies(build_amm(arm, n_modes, reference_q=q_r), q_r)
        if previous is not None:
            assert np.all(omega[: previous.size] <= previous * (1 + 1e-10))
            changes.append(1 - omega[:3] / previous[:3])
        previous = omega
    changes = np.array(changes)  # relative drop of the lowest three, 1->2, 2->3, 3->4 modes
    assert np.all(np.diff(changes, axis=0) <= 1e-12) and np.all(changes[-1] < 1e-4)


@pytest.mark.parametrize("damping", ["ratio", "paper"])
def test_single_link_modal_damping_ratio(model_path, damping):
    """Locked single link: each mode is decoupled, so its damping ratio is the file's zeta
    (``damping="ratio"``) or zeta / m_l (Eq 68 as printed, ``damping="paper"``)."""
    zeta = 0.03
    arm = _arm(model_path, 1)
    arm = dataclasses.replace(
        arm, links=(dataclasses.replace(arm.links[0], damping_ratios=(zeta,)),)
    )
    model = build_amm(arm, 3, damping=damping)
    N = model.n_q
    xs = ca.MX.sym("x", 2 * N)
    A = np.array(
        ca.Function("lin", [xs], [ca.jacobian(model.functions["f"](xs, ca.MX.zeros(1)), xs)])(
            np.zeros(2 * N)
        )
    )
    M = model.mass_matrix(np.zeros(N))
    # tangent stiffness and damping of the whole model; clamping the joint keeps the elastic block
    K_t, D_t = -M @ A[N:, :N], -M @ A[N:, N:]
    M_ff, K_ff, D_ff = M[1:, 1:], K_t[1:, 1:], D_t[1:, 1:]
    n_f = N - 1
    A_locked = np.block(
        [
            [np.zeros((n_f, n_f)), np.eye(n_f)],
            [-np.linalg.solve(M_ff, K_ff), -np.linalg.solve(M_ff, D_ff)],
        ]
    )
    lam = np.linalg.eigvals(A_locked)
    lam = lam[lam.imag > 0]
    ratios = np.sort(-lam.real / np.abs(lam))
    expected = zeta if damping == "ratio" else zeta / arm.links[0].mass
    np.testing.assert_allclose(ratios, expected, rtol=1e-9)
