"""Tests of flexctrl.beam.clamped_mass against independent references.

References used here never call the module's closed forms: classical frequency
equations solved in the test, a Hermite-cubic finite-element beam, composite
Gauss-Legendre quadrature of the returned shapes, and exact rational arithmetic for
the tip quadratic form of Eq 40.
"""

from __future__ import annotations

import math
import warnings
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.linalg import eigh
from scipy.optimize import brentq

from flexctrl.beam.clamped_mass import (
    ClampedMassModes,
    IndefiniteTipInertiaWarning,
    clamped_mass_modes,
)
from flexctrl.beam.clamped_mass_roots import ROOT_RTOL, frequency_determinant

LINK = dict(length=0.8, rho=1.3, EI=40.0)  # a generic link for the property tests


# --- independent references ------------------------------------------------------------
def classical_roots(f, n, hi=22.0, step=1e-3):
    """First ``n`` sign changes of ``f`` on (0, hi], polished by brentq."""
    grid = np.arange(step, hi, step)
    vals = np.array([f(x) for x in grid])
    idx = np.nonzero(np.sign(vals[:-1]) * np.sign(vals[1:]) < 0)[0][:n]
    return np.array([brentq(f, grid[i], grid[i + 1], xtol=1e-15) for i in idx])


def fe_matrices(length, rho, EI, m, J, M, n_el):
    """Hermite-cubic beam, consistent mass, clamped at node 0, tip body at the last node."""
    h = length / n_el
    ke = (
        EI
        / h**3
        * np.array(
            [
                [12, 6 * h, -12, 6 * h],
                [6 * h, 4 * h * h, -6 * h, 2 * h * h],
                [-12, -6 * h, 12, -6 * h],
                [6 * h, 2 * h * h, -6 * h, 4 * h * h],
            ]
        )
    )
    me = (
        rho
        * h
        / 420
        * np.array(
            [
                [156, 22 * h, 54, -13 * h],
                [22 * h, 4 * h * h, 13 * h, -3 * h * h],
                [54, 13 * h, 156, -22 * h],
                [-13 * h, -3 * h * h, -22 * h, 4 * h * h],
            ]
        )
    )
    nd = 2 * (n_el + 1)
    K, Mm = np.zeros((nd, nd)), np.zeros((nd, nd))
    for e in range(n_el):
        sl = slice(2 * e, 2 * e + 4)
        K[sl, sl] += ke
        Mm[sl, sl] += me
    Mm[-2:, -2:] += np.array([[m, M], [M, J]])
    return K[2:, 2:], Mm[2:, 2:]


def fe_omega(length, rho, EI, m=0.0, J=0.0, M=0.0, n_el=120, n=6):
    """Lowest ``n`` positive natural frequencies (rad/s) of the FE model.

    Solved as ``M v = (1/omega^2) K v`` (``K`` is positive definite), which also
    serves an indefinite tip inertia.
    """
    K, Mm = fe_matrices(length, rho, EI, m, J, M, n_el)
    inv = eigh(Mm, K, eigvals_only=True)
    inv = np.sort(inv[inv > 0])[::-1]
    return np.sqrt(1.0 / inv[:n])


_XG, _WG = np.polynomial.legendre.leggauss(40)


def quad(f, length, panels=16):
    """Composite Gauss-Legendre quadrature of ``f(x)`` (last axis) over [0, length]."""
    h = length / panels
    total = 0.0
    for a in np.arange(panels) * h:
        x = a + 0.5 * h * (_XG + 1.0)
        total = total + f(x) @ (0.5 * h * _WG)
    return total


def tip_form(modes: ClampedMassModes):
    """Eq-40 tip terms ``u_j^T T u_k`` evaluated exactly (fractions) for the given floats."""
    u = [
        (Fraction(float(a)), Fraction(float(b)))
        for a, b in zip(modes.tip_deflection, modes.tip_slope)
    ]
    m, J, M = Fraction(modes.m_tip), Fraction(modes.J_tip), Fraction(modes.M_tip)
    n = modes.n_modes
    out = np.zeros((n, n))
    for j in range(n):
        for k in range(n):
            (a, b), (c, d) = u[j], u[k]
            out[j, k] = float(m * a * c + M * (a * d + b * c) + J * b * d)
    return out


def tip_scale(modes: ClampedMassModes):
    """``|u|^T |T| |u|`` per pair: the size of the terms Eq 40 sums."""
    a, b = np.abs(modes.tip_deflection), np.abs(modes.tip_slope)
    return (
        modes.m_tip * np.outer(a, a)
        + abs(modes.M_tip) * (np.outer(a, b) + np.outer(b, a))
        + modes.J_tip * np.outer(b, b)
    )


def check_modes(modes: ClampedMassModes):
    """Eq 40, Eqs 50-53 and the boundary conditions by quadrature of the returned shapes."""
    L, rho, EI, ml = modes.length, modes.rho, modes.EI, modes.link_mass
    n = modes.n_modes
    phi = lambda x: modes.shape(x)  # noqa: E731
    z = quad(lambda x: rho * phi(x)[:, None, :] * phi(x)[None, :, :], L)
    ortho = (z + tip_form(modes)) / ml
    tol = 1e-10 + 1e-15 * tip_scale(modes) / ml
    assert np.all(np.abs(ortho - np.eye(n)) <= tol), np.abs(ortho - np.eye(n)).max()
    assert np.allclose(modes.z, z, rtol=0, atol=1e-12 * ml)
    assert np.allclose(modes.v, quad(lambda x: rho * phi(x), L), rtol=0, atol=1e-12 * ml)
    assert np.allclose(modes.w, quad(lambda x: rho * x * phi(x), L), rtol=0, atol=1e-12 * ml * L)
    energy = quad(lambda x: EI * modes.shape(x, 2) ** 2, L)
    assert np.allclose(energy, modes.stiffness, rtol=1e-9, atol=0)
    # clamped root, tip conditions (scaled by the size of their terms)
    root = modes.shape(np.array([0.0, 0.0]), 0)[:, 0], modes.shape(np.array([0.0]), 1)[:, 0]
    assert np.all(np.abs(root[0]) <= 1e-13) and np.all(
        np.abs(root[1]) <= 1e-12 * modes.beta + 1e-13
    )
    d = [modes.shape(np.array([L]), k)[:, 0] for k in range(4)]
    w2 = modes.omega**2
    assert np.allclose(d[0], modes.tip_deflection, rtol=1e-13, atol=1e-14)
    assert np.allclose(d[1], modes.tip_slope, rtol=1e-13, atol=1e-14 * modes.beta)
    # tip conditions, up to the absolute accuracy of the tip values (1e-12 in phi, 1e-12 beta
    # in phi'): a near-rigid tip constraint makes them tiny differences of O(1) terms
    b, m, J, M = modes.beta, modes.m_tip, modes.J_tip, abs(modes.M_tip)
    lhs, rhs = EI * d[2], w2 * (J * d[1] + modes.M_tip * d[0])
    scale = np.abs(lhs) + w2 * (J * (np.abs(d[1]) + 1e3 * b) + M * (np.abs(d[0]) + 1e3)) + EI * b**2
    assert np.all(np.abs(lhs - rhs) <= 1e-9 * scale)
    lhs, rhs = EI * d[3], -w2 * (m * d[0] + modes.M_tip * d[1])
    scale = np.abs(lhs) + w2 * (m * (np.abs(d[0]) + 1e3) + M * (np.abs(d[1]) + 1e3 * b)) + EI * b**3
    assert np.all(np.abs(lhs - rhs) <= 1e-9 * scale)


# --- frequencies -----------------------------------------------------------------------
def test_clamped_free_textbook_roots():
    modes = clamped_mass_modes(1.0, 1.0, 1.0, 6)
    textbook = [1.87510, 4.69409, 7.85476, 10.99554, 14.13717]
    assert np.allclose(modes.beta[:5], textbook, rtol=0, atol=6e-6)
    ref = classical_roots(lambda x: 1.0 / math.cosh(x) + math.cos(x), 6)
    assert np.allclose(modes.beta, ref, rtol=1e-12)


@pytest.mark.parametrize("mu", [1e-3, 0.2, 1.0, 5.0, 80.0])
def test_point_mass_against_classical_equation(mu):
    L, rho = 1.7, 0.9
    modes = clamped_mass_modes(L, rho, 12.0, 6, m_tip=mu * rho * L)

    def f(x):  # (1 + cos cosh + mu x (cos sinh - sin cosh)) / cosh
        return 1 / math.cosh(x) + math.cos(x) + mu * x * (math.cos(x) * math.tanh(x) - math.sin(x))

    assert np.allclose(modes.beta * L, classical_roots(f, 6), rtol=1e-11)


@pytest.mark.parametrize(
    "m,J,M",
    [
        (0.0, 0.3, 0.0),
        (0.5, 0.02, 0.0),
        (1.0, 0.05, 0.1),
        (0.8, 0.1, -0.2),
        (2.0, 3.2e-4, 0.0),
        (0.3, 0.3 * 0.4**2, 0.3 * 0.4),
    ],
)
def test_tip_body_against_finite_elements(m, J, M):
    L, rho, EI = 1.2, 0.75, 30.0
    modes = clamped_mass_modes(L, rho, EI, 4, m, J, M)
    fe = fe_omega(L, rho, EI, m, J, M, n_el=160, n=4)
    assert np.allclose(modes.omega, fe, rtol=1e-6)


def test_subedi_table3_link3():
    no_payload = clamped_mass_modes(1.5, 0.7425, 2.4114e3, 2)
    payload = clamped_mass_modes(1.5, 0.7425, 2.4114e3, 2, m_tip=2.0, J_tip=3.2e-4, M_tip=0.0)
    assert np.allclose(no_payload.frequency_hz, [14.17, 88.82], rtol=0, atol=0.01)
    assert np.allclose(payload.frequency_hz, [4.90, 63.97], rtol=0, atol=0.01)


def test_huge_tip_mass_limit():
    L, rho, EI, m = 1.0, 1.0, 1.0, 1e4
    modes = clamped_mass_modes(L, rho, EI, 4, m_tip=m)
    pinned = classical_roots(lambda x: math.cos(x) * math.tanh(x) - math.sin(x), 3)  # tan = tanh
    assert np.allclose(pinned[:2], [3.9266, 7.0686], atol=1e-4)
    assert np.allclose(modes.beta[1:] * L, pinned, rtol=1e-4)
    assert modes.omega[0] == pytest.approx(math.sqrt(3 * EI / (m * L**3)), rel=1e-4)


def test_huge_tip_inertia_limit():
    # J -> inf blocks the tip slope while the shear stays free: clamped-sliding beam,
    # phi'(L) = phi'''(L) = 0  =>  cos sinh + sin cosh = 0; the first mode is the body
    # rocking on the cantilever's rotational stiffness EI / L (tip moment, free tip).
    L, rho, EI, J = 1.0, 1.0, 1.0, 1e4
    modes = clamped_mass_modes(L, rho, EI, 4, J_tip=J)
    sliding = classical_roots(lambda x: math.cos(x) * math.tanh(x) + math.sin(x), 3)
    assert np.allclose(modes.beta[1:] * L, sliding, rtol=1e-4)
    assert modes.omega[0] == pytest.approx(math.sqrt(EI / (J * L)), rel=1e-4)
    both = clamped_mass_modes(
        L, rho, EI, 4, m_tip=1e4, J_tip=1e4
    )  # clamped-clamped beyond two body modes
    clamped = classical_roots(lambda x: 1 / math.cosh(x) - math.cos(x), 2)
    assert np.allclose(both.beta[2:] * L, clamped, rtol=1e-4)


# --- modes and modal integrals ---------------------------------------------------------
@pytest.mark.parametrize(
    "m,J,M",
    [
        (0.0, 0.0, 0.0),
        (2.0, 3.2e-4, 0.0),
        (0.7, 0.05, -0.15),
        (1e4, 0.0, 0.0),
        (0.0, 1e4, 0.0),
        (1e4, 1e4, 9e3),
        (1e-9, 1e-9, 0.0),
        (50.0, 2.0, -10.0),
    ],
)
def test_modes_orthonormal_integrals_and_bcs(m, J, M):
    check_modes(clamped_mass_modes(**LINK, n_modes=6, m_tip=m, J_tip=J, M_tip=M))


def test_sine_cosine_coefficients_reproduce_the_shape():
    modes = clamped_mass_modes(**LINK, n_modes=3, m_tip=0.4, J_tip=0.01, M_tip=0.03)
    x = np.linspace(0, LINK["length"], 7)
    bx = np.outer(modes.beta, x)
    c = modes.coefficients
    assert np.allclose(c[:, 2], -c[:, 0]) and np.allclose(c[:, 3], -c[:, 1])
    direct = (
        c[:, :1] * np.sin(bx)
        + c[:, 1:2] * np.cos(bx)
        + c[:, 2:3] * np.sinh(bx)
        + c[:, 3:4] * np.cosh(bx)
    )
    assert np.allclose(direct, modes.shape(x), rtol=0, atol=1e-9)
    assert np.all(modes.tip_deflection > 0)


def test_zero_modes():
    modes = clamped_mass_modes(1.0, 1.0, 1.0, 0, m_tip=1.0)
    assert modes.beta.shape == (0,) and modes.coefficients.shape == (0, 4)
    assert modes.z.shape == (0, 0) and modes.v.shape == (0,) and modes.w.shape == (0,)
    assert modes.shape(np.linspace(0, 1, 5)).shape == (0, 5)
    assert modes.omega.shape == modes.stiffness.shape == modes.tip_slope.shape == (0,)


def test_shape_argument_checks_and_shapes():
    modes = clamped_mass_modes(1.0, 1.0, 1.0, 2)
    assert modes.shape(0.5).shape == (2,)
    assert modes.shape(np.zeros((3, 4)), derivative=3).shape == (2, 3, 4)
    with pytest.raises(ValueError, match="derivative"):
        modes.shape(0.5, derivative=4)
    with pytest.raises(ValueError, match="x must lie"):
        modes.shape([0.2, 1.5])


# --- indefinite tip inertia ------------------------------------------------------------
def test_indefinite_tip_inertia_warns_and_matches_fe():
    m, J, M = 2.0, 0.1, 0.6  # M^2 = 0.36 > m J = 0.2
    with pytest.warns(IndefiniteTipInertiaWarning, match="indefinite"):
        modes = clamped_mass_modes(**LINK, n_modes=5, m_tip=m, J_tip=J, M_tip=M)
    fe = fe_omega(**LINK, m=m, J=J, M=M, n_el=200, n=5)
    assert np.allclose(modes.omega, fe, rtol=1e-6)
    check_modes(modes)


def test_psd_tip_does_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        clamped_mass_modes(1.0, 1.0, 1.0, 3, m_tip=2.0, J_tip=0.5, M_tip=1.0)  # singular PSD


# --- properties over random tips -------------------------------------------------------
log_value = st.one_of(st.just(0.0), st.floats(-9.0, 4.0).map(lambda e: 10.0**e))
tips = st.tuples(log_value, log_value, st.floats(-1.0, 1.0))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(tip=tips, n=st.integers(0, 6))
def test_roots_match_fe_count_order_and_modes(tip, n):
    m, J, s = tip
    M = s * math.sqrt(m * J)
    modes = clamped_mass_modes(**LINK, n_modes=n, m_tip=m, J_tip=J, M_tip=M)
    assert modes.beta.shape == (n,)
    assert np.all(np.diff(modes.beta) > 1e-6 * modes.beta[1:])
    if n:
        assert np.allclose(modes.omega, fe_omega(**LINK, m=m, J=J, M=M, n_el=100, n=n), rtol=1e-4)
        check_modes(modes)
        lam = modes.beta * LINK["length"]
        ml = LINK["rho"] * LINK["length"]
        mu, eta, kappa = m / ml, J / (ml * LINK["length"] ** 2), M / (ml * LINK["length"])
        det = frequency_determinant(lam, mu, eta, kappa)
        assert np.all(np.abs(det) <= root_residual_bound(lam, mu, eta, kappa))


def root_residual_bound(lam, mu, eta, kappa):
    """How far from zero the scaled determinant may be at a root found to rounding.

    Two parts. The root finder stops within ``ROOT_RTOL`` (8.9e-16) of ``lam`` (relative),
    which moves the determinant by at most its slope times that step (slope by central
    difference here; four times the step for brentq's bracket). And the determinant is
    evaluated in floating point: each term of ``Delta / (cosh W)`` carries rounding of
    about ``eps`` times its own size, and ``d = mu eta - kappa^2`` carries
    ``eps (mu eta + kappa^2)`` -- near ``kappa^2 = mu eta`` (the hypothesis draws
    ``|s| = 1``) that is far more than ``d`` itself, and it is multiplied by ``lam^4``.
    Sixteen times that sum covers the few roundings per term. At tip (1000 kg,
    10 kg m^2, s = 1) the fifth root's ``|det|`` is 1.08e-12 against a bound of about
    4e-11; an absolute 1e-12 had no such reason and failed there. How sharp it is depends
    on the tip: a root moved by 1e-11 relative fails it for ordinary tips, but where the
    rounding of ``d`` dominates (heavy tips with ``|s| = 1``, e.g. 1e4 kg, 1e4 kg m^2) a
    move has to reach about 2e-11 to 2e-10 -- still far below what a wrong root would be.
    """
    lam = np.asarray(lam, dtype=float)
    eps = np.finfo(float).eps
    l2 = lam * lam
    size = (
        2.0
        + mu * lam
        + 2.0 * abs(kappa) * l2
        + eta * lam * l2
        + (mu * eta + kappa * kappa) * l2 * l2
    )
    w = (
        1.0
        + mu * lam
        + 2.0 * abs(kappa) * l2
        + eta * lam * l2
        + abs(mu * eta - kappa * kappa) * l2 * l2
    )
    h = 1e-7 * lam
    slope = (
        frequency_determinant(lam + h, mu, eta, kappa)
        - frequency_determinant(lam - h, mu, eta, kappa)
    ) / (2 * h)
    return 16.0 * eps * size / w + 4.0 * ROOT_RTOL * lam * np.abs(slope)


@settings(max_examples=60, deadline=None)
@given(tip=tips, factor=st.floats(1.0, 1e3), which=st.sampled_from(["m_tip", "J_tip"]))
def test_frequencies_do_not_increase_with_tip_mass_or_inertia(tip, factor, which):
    m, J, s = tip
    base = dict(m_tip=m, J_tip=J, M_tip=s * math.sqrt(m * J))
    heavier = dict(base, **{which: base[which] * factor + 1e-6})
    w0 = clamped_mass_modes(**LINK, n_modes=6, **base).omega
    w1 = clamped_mass_modes(**LINK, n_modes=6, **heavier).omega
    assert np.all(w1 <= w0 * (1 + 1e-12))


@settings(max_examples=40, deadline=None)
@given(lam=st.floats(0.0, 40.0), mu=st.floats(0, 1e6), eta=st.floats(0, 1e6), s=st.floats(-2, 2))
def test_frequency_determinant_is_bounded(lam, mu, eta, s):
    f = frequency_determinant(lam, mu, eta, s * math.sqrt(mu * eta))
    assert isinstance(f, float) and abs(f) <= 2.0 + 1e-12


# --- argument validation ---------------------------------------------------------------
@pytest.mark.parametrize(
    "kwargs,name",
    [
        (dict(length=0.0), "length"),
        (dict(length=-1.0), "length"),
        (dict(rho=0.0), "rho"),
        (dict(EI=-2.0), "EI"),
        (dict(EI=float("nan")), "EI"),
        (dict(length=float("inf")), "length"),
        (dict(m_tip=-1e-3), "m_tip"),
        (dict(J_tip=-1.0), "J_tip"),
        (dict(m_tip=float("nan")), "m_tip"),
        (dict(M_tip=float("nan")), "M_tip"),
        (dict(n_modes=-1), "n_modes"),
        (dict(n_modes=7), "n_modes"),
    ],
)
def test_invalid_arguments_raise_value_error(kwargs, name):
    args = dict(length=1.0, rho=1.0, EI=1.0, n_modes=2) | kwargs
    with pytest.raises(ValueError) as err:
        clamped_mass_modes(**args)
    msg = str(err.value)
    assert name in msg and repr(kwargs[name]) in msg
    assert "0..6" in msg if name == "n_modes" else ("positive" in msg or "finite" in msg)


@pytest.mark.parametrize("n", [2.0, "2", True])
def test_non_integer_mode_count_raises_type_error(n):
    with pytest.raises(TypeError):
        clamped_mass_modes(1.0, 1.0, 1.0, n)
