"""Correction shapes added to the clamped-mass modes (flexctrl.modal.static_correction), checked
against closed forms and a quadrature independent of the module's own rule."""

import warnings

import numpy as np
import pytest

import flexctrl as fc
from flexctrl.modal.arm_modes import link_modes
from flexctrl.modal.static_correction import CorrectedModes, pinned_root_shapes


@pytest.fixture(scope="module")
def arm():
    return fc.load_arm("models/subedi3link.toml").with_payload(2.0)


def _gram(modes, corrected, derivative):
    """Gram matrix of the shapes by the trapezoid rule on 40001 points (not the module's Gauss
    rule)."""
    x = np.linspace(0.0, modes.length, 40001)
    f = corrected.shape(x, derivative)
    return np.trapezoid(f[:, None] * f[None], x, axis=-1)


@pytest.mark.parametrize("link, kind", [(1, "tip_moment"), (0, "tip_moment"), (2, "pinned_root")])
def test_corrected_shapes_are_mass_and_stiffness_orthonormal(arm, link, kind):
    base = link_modes(arm, None, link, 3)
    extra = pinned_root_shapes(arm, None, link, 2) if kind == "pinned_root" else None
    c = CorrectedModes(base, extra)
    T = np.array([[base.m_tip, base.M_tip], [base.M_tip, base.J_tip]])
    tip = np.vstack([c.tip_deflection, c.tip_slope])
    mass = base.rho * _gram(base, c, 0) + tip.T @ T @ tip  # Eq 40's inner product with the tip body
    stiff = base.EI * _gram(base, c, 2)
    assert np.allclose(mass / base.link_mass, np.eye(c.n_modes), atol=1e-7)
    # trapezoid on piecewise-linear curvature (pinned shapes): 1e-4; smooth shapes: 1e-7
    tol = 2e-4 if kind == "pinned_root" else 1e-6
    assert np.allclose(
        stiff / (base.link_mass * np.outer(c.omega, c.omega)), np.eye(c.n_modes), atol=tol
    )
    # the clamped-mass modes and their frequencies are untouched
    assert np.array_equal(c.omega[:3], base.omega)
    assert np.allclose(
        c.shape(np.linspace(0, base.length, 7))[:3], base.shape(np.linspace(0, base.length, 7))
    )
    # admissible: clamped at the root
    assert np.allclose(c.shape(np.array([0.0]))[:, 0], 0.0) and np.allclose(
        c.shape(np.array([0.0]), 1)[:, 0], 0.0, atol=1e-9
    )
    x = np.linspace(0.0, base.length, 40001)
    assert np.allclose(c.v, base.rho * np.trapezoid(c.shape(x), x), rtol=1e-6, atol=1e-9)
    assert np.allclose(c.w, base.rho * np.trapezoid(x * c.shape(x), x), rtol=1e-6, atol=1e-9)
    assert np.allclose(c.z, base.rho * _gram(base, c, 0), atol=1e-7)


def test_tip_moment_correction_gives_the_closed_form_static_deflection(arm):
    """Static answer to a tip moment M0 in the corrected basis: w(L) = M0 L^2 / (2 EI), w'(L) =
    M0 L / EI."""
    base = link_modes(arm, None, 1, 2)
    M0 = 50.0
    for c, exact in ((CorrectedModes(base), True), (base, False)):
        q = M0 * c.tip_slope / (base.link_mass * c.omega**2)  # K q = f, f_j = M0 phi_j'(L)
        w, dw = c.tip_deflection @ q, c.tip_slope @ q
        w_exact, dw_exact = M0 * base.length**2 / (2 * base.EI), M0 * base.length / base.EI
        if exact:
            assert w == pytest.approx(w_exact, rel=1e-9) and dw == pytest.approx(dw_exact, rel=1e-9)
        else:  # the clamped-mass modes alone hold it closely (1.2e-4; assumed-modes.md)
            assert 1e-6 < abs(dw / dw_exact - 1) < 1e-3


def test_build_amm_with_correction_adds_one_shape_per_inner_link_and_lowers_locked_frequencies(arm):
    from flexctrl.dynamics.amm import build_amm

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = build_amm(arm, 2)
        corrected = build_amm(arm, 2, static_correction=True)
    assert plain.n_q == 3 + 6 and corrected.n_q == 3 + 8
    assert corrected.info["static_correction"] == [True, True, False]
    assert "static-correction" in corrected.name and "static-correction" not in plain.name
    a, b = (
        np.array(plain.info["locked_frequencies_rad_s"]),
        np.array(corrected.info["locked_frequencies_rad_s"]),
    )
    # Rayleigh-Ritz: a larger basis lowers (never raises) every locked frequency
    assert np.all(b[: a.size] <= a * (1 + 1e-9))
    # the default is off: the model is the one without correction
    assert plain.info["static_correction"] == [False, False, False]
