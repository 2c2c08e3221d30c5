"""Axially compliant assumed-modes links (``axial_stretch``; ``docs/explanation/assumed-modes.md``
section 14).

References independent of the model code: the exact first axial frequency of a clamped rod with
a tip mass (``beta L tan(beta L) = m / M``), the exact tip elongation of a hanging rod under its
own weight and a tip weight, the finite-element model's locked-joint spectrum (axially compliant
by construction), and RK4's order in the energy balance.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from model_checks import energy_drift, one_link
from scipy.optimize import brentq

from flexctrl.dynamics.amm import build_amm
from flexctrl.dynamics.build import build_model
from flexctrl.dynamics.fem.locked_spectrum import locked_fem_hz
from flexctrl.errors import SpecError
from flexctrl.spec.arm import load_arm


@pytest.fixture
def arm(model_path):
    return load_arm(model_path)


def _locked(model, q):
    """Locked-joint frequencies (rad/s) of ``model`` at joint angles ``q``, sorted."""
    n = model.n_joints
    x = np.concatenate([q, np.zeros(model.n_q - n)])
    M = model.mass_matrix(x)[n:, n:]
    K = np.array(model.functions["K"]()["K"])[n:, n:]
    lam = np.linalg.eigvals(np.linalg.solve(0.5 * (M + M.T), K)).real
    return np.sort(np.sqrt(lam))


@pytest.mark.parametrize("payload", [2.0, 10.0])
def test_axial_frequency_of_one_link_against_the_rod_with_a_tip_mass(arm, payload):
    """Straight single link: the one new locked frequency is the axial one.  The exact rod gives
    omega = beta sqrt(EA / rho) with beta L tan(beta L) = m / M; a uniform strain is its Rayleigh
    quotient, so it lies above the exact value and within 0.5 % (2 kg) / 0.05 % (10 kg)."""
    one = one_link(arm, payload)
    link = one.links[0]
    without, with_ = (
        _locked(build_amm(one, 2, axial_stretch=flag), [0.0]) for flag in (False, True)
    )
    new = [w for w in with_ if np.min(np.abs(without - w) / w) > 1e-9]
    assert len(new) == 1 and np.allclose(np.sort(np.setdiff1d(with_, new)), without, rtol=1e-9)
    ratio = link.mass / payload
    bL = brentq(lambda b: b * math.tan(b) - ratio, 1e-9, math.pi / 2 - 1e-9)
    exact = bL / link.length * math.sqrt(link.axial_stiffness() / link.mass_per_length)
    rel = new[0] / exact - 1.0
    assert 0.0 < rel < (5e-3 if payload == 2.0 else 5e-4), rel


def test_hanging_link_stretches_by_the_closed_form(arm):
    """A link hanging under gravity with a tip weight: the exact tip elongation of the rod,
    int_0^L N(x) / EA dx = (M + m / 2) g L / EA, is what the uniform strain gives at equilibrium."""
    one = one_link(arm, 3.0, gravity=(0.0, -9.81))
    model = build_amm(one, 2, axial_stretch=True)
    link = one.links[0]
    k = model.coordinate_names.index("e1")
    q = np.zeros(model.n_q)
    q[0] = -math.pi / 2  # pointing down
    g = np.asarray(model.functions["g"](q), dtype=float).ravel()
    K = np.array(model.functions["K"]()["K"])
    elongation = -g[k] / K[k, k]
    exact = (3.0 + 0.5 * link.mass) * 9.81 * link.length / link.axial_stiffness()
    assert elongation == pytest.approx(exact, rel=1e-9)
    assert np.allclose(g[1:k], 0.0, atol=1e-9)  # gravity along the link does not bend it


def test_straight_arm_bending_frequencies_unchanged(arm):
    """At straight links the elongations decouple from bending at first order: Table 3's
    frequencies stay, the axial ones come on top."""
    loaded = arm.with_payload(2.0)
    off, on = (build_amm(loaded, 2, axial_stretch=flag) for flag in (False, True))
    w_off, w_on = _locked(off, [0.0] * 3), _locked(on, [0.0] * 3)
    assert w_on.size == w_off.size + 3
    assert all(np.min(np.abs(w_on - w) / w) < 1e-9 for w in w_off)


@pytest.mark.parametrize("q_deg", [(0.0, 90.0, -45.0), (0.0, 60.0, 90.0)])
def test_bent_arm_frequencies_meet_the_finite_elements(arm, q_deg):
    """At bent configurations an inboard link's stretch moves the outboard arm sideways, so the
    rigid-link assumed modes sit 0.01-0.2 % above the (axially compliant) finite elements.  With
    the elongations the lowest six agree with FEM-16 ten times better than without."""
    loaded = arm.with_payload(2.0)
    fem = 2 * math.pi * locked_fem_hz(loaded, 16, q_deg, n_modes=6)
    q = np.radians(q_deg)
    off, on = (
        _locked(build_amm(loaded, 4, reference_q=q, axial_stretch=flag), q)[:6]
        for flag in (False, True)
    )
    err_off, err_on = np.abs(off / fem - 1), np.abs(on / fem - 1)
    assert err_off.max() > 5e-4  # the discrepancy the elongations are for
    assert err_on.max() < 0.1 * err_off.max(), (err_on, err_off)


def test_energy_conserved_at_rk4_order(arm):
    """Undamped free swing under gravity with shortening and stretch: the energy error of RK4
    falls by at least 2^3.5 when the step halves."""
    a = dataclasses.replace(
        arm.with_payload(2.0),
        links=tuple(dataclasses.replace(l, damping_ratios=(0.0,)) for l in arm.links),
        joints=tuple(dataclasses.replace(j, friction=0.0) for j in arm.joints),
        axial_shortening=True,
        axial_stretch=True,
    )
    model = build_model(a, "amm:2")
    assert model.info["axial_stretch"] is True and model.coordinate_names[-3:] == ("e1", "e2", "e3")
    x0 = np.zeros(model.n_x)
    x0[[0, 1, 2]] = [0.2, -0.3, 0.4]
    x0[model.coordinate_names.index("qf31")] = 0.05
    x0[model.coordinate_names.index("e2")] = 1e-5
    x0[model.n_q : model.n_q + 3] = [1.0, -2.0, 3.0]
    coarse, swing = energy_drift(model, x0, 1e-4)
    fine, _ = energy_drift(model, x0, 5e-5)
    assert swing > 0.05
    assert fine < 1e-5
    assert coarse / fine > 2**3.5


def test_switch_reaches_the_model_and_bad_values_are_refused(model_path, tmp_path):
    from flexctrl.scenes.arm_setup import scene_arm
    from flexctrl.spec.scene import load_scene

    assert load_arm(model_path).axial_stretch is None
    assert build_model(load_arm(model_path), "amm:1").info["axial_stretch"] is False  # default off
    assert build_model(load_arm(model_path, ["axial_stretch=true"]), "amm:1").n_q == 3 + 3 + 3
    with pytest.raises(SpecError, match="axial_stretch"):
        load_arm(model_path, ["axial_stretch=1"])
    with pytest.raises(SpecError, match="finite-element"):
        build_model(load_arm(model_path, ["axial_stretch=false"]), "fem:1")
    with pytest.raises(SpecError, match="frozen"):
        build_model(load_arm(model_path, ["axial_stretch=true"]), "amm:1", modes="scheduled")
    scene_file = tmp_path / "s.toml"
    scene_file.write_text(
        f'kind = "arm"\nmodel = "{model_path}"\ndt = 1e-3\nduration = 0.01\naxial_stretch = true\n'
    )
    scene = load_scene(scene_file)
    assert scene.axial_stretch is True and scene_arm(scene).axial_stretch is True
    assert build_model(scene_arm(scene), "amm:1").info["axial_stretch"] is True


def _damped_locked(model, q, count):
    """Frequencies (rad/s) and damping ratios of the ``count`` slowest locked-joint modes of
    ``model`` at ``q``."""
    n = model.n_joints
    x = np.concatenate([q, np.zeros(model.n_q - n)])
    M = model.mass_matrix(x)[n:, n:]
    K = np.array(model.functions["K"]()["K"])[n:, n:]
    D = np.array(model.functions["D"]()["D"])[n:, n:]
    m = M.shape[0]
    A = np.block([[np.zeros((m, m)), np.eye(m)], [-np.linalg.solve(M, K), -np.linalg.solve(M, D)]])
    lam = np.linalg.eigvals(A)
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(np.abs(lam))][:count]
    return np.abs(lam), -lam.real / np.abs(lam)


def test_stiffness_damping_form_damps_like_the_finite_elements(arm):
    """``damping_form = "stiffness"``: the assumed modes' locked modes get the damping ratios of the
    finite elements' (2 zeta / omega_1) K, where modal ratios leave the higher modes at zeta."""
    a = dataclasses.replace(
        arm.with_payload(2.0),
        links=tuple(dataclasses.replace(l, damping_ratios=(0.005,)) for l in arm.links),
    )
    q = np.zeros(3)
    w_fem, z_fem = _damped_locked(build_model(a, "fem:8"), q, 5)
    w_st, z_st = _damped_locked(build_model(a, "amm:4", damping="stiffness"), q, 5)
    _, z_ratio = _damped_locked(build_model(a, "amm:4", damping="ratio"), q, 5)
    assert np.allclose(w_st, w_fem, rtol=2e-3)
    assert np.allclose(z_st, z_fem, rtol=2e-2), (z_st, z_fem)
    assert np.all(z_fem[3:] > 2 * z_ratio[3:])  # the modal ratios would be far off


def test_links_without_modes_stay_rigid(arm):
    """``rigid`` (amm:0) is unchanged by the switch, and only links with elastic modes get an
    elongation."""
    loaded = arm.with_payload(2.0)
    rigid_on, rigid_off = (build_amm(loaded, 0, axial_stretch=flag) for flag in (True, False))
    assert rigid_on.coordinate_names == rigid_off.coordinate_names == ("q1", "q2", "q3")
    q = np.array([0.3, -0.5, 0.8])
    assert np.array_equal(
        np.asarray(rigid_on.functions["M"](q)), np.asarray(rigid_off.functions["M"](q))
    )
    mixed = build_amm(loaded, [2, 0, 1], axial_stretch=True)
    assert mixed.coordinate_names[-2:] == ("e1", "e3") and mixed.n_q == 3 + 3 + 2
