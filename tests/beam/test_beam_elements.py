"""Beam element matrices against independent computations (flexctrl.beam.elements)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sl
from numpy.polynomial import polynomial as P
from scipy.optimize import brentq
from scipy.special import jv

from flexctrl.beam import elements as el


def hermite_polys(l: float) -> list[np.ndarray]:
    """Shape functions built from their definition: cubic p with prescribed (p, p') at 0 and l."""
    V = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [1, l, l**2, l**3], [0, 1, 2 * l, 3 * l**2]], float)
    coeffs = np.linalg.solve(V, np.eye(4))  # column k: coefficients of N_k
    return [coeffs[:, k] for k in range(4)]


def integral(c: np.ndarray, l: float) -> float:
    ci = P.polyint(c)
    return P.polyval(l, ci) - P.polyval(0.0, ci)


@pytest.mark.parametrize("l", [0.3, 1.0, 2.7])
def test_element_matrices_match_integrals_of_shape_functions(l):
    rho, EI = 2.5, 7.0
    N = hermite_polys(l)
    d1 = [P.polyder(c) for c in N]
    d2 = [P.polyder(c, 2) for c in N]
    M = rho * np.array([[integral(P.polymul(a, b), l) for b in N] for a in N])
    K = EI * np.array([[integral(P.polymul(a, b), l) for b in d2] for a in d2])
    np.testing.assert_allclose(el.beam_mass(rho, l), M, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(el.beam_stiffness(EI, l), K, rtol=1e-12, atol=1e-12)
    # geometric stiffness for a linear and a quadratic axial force
    F1, F2 = 3.0, -1.5
    lin = np.array([F1, (F2 - F1) / l])
    Kg = np.array([[integral(P.polymul(lin, P.polymul(a, b)), l) for b in d1] for a in d1])
    np.testing.assert_allclose(el.geometric_stiffness_linear(F1, F2, l), Kg, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(
        el.geometric_stiffness(lambda z: P.polyval(z, lin), l), Kg, rtol=1e-12, atol=1e-12
    )
    quint = np.array([1.0, -2.0, 0.7, 0.3, -0.2, 0.05])  # degree 5: still exact
    Kq = np.array([[integral(P.polymul(quint, P.polymul(a, b)), l) for b in d1] for a in d1])
    np.testing.assert_allclose(
        el.geometric_stiffness(lambda z: P.polyval(z, quint), l), Kq, rtol=1e-11, atol=1e-12
    )
    # shape functions and derivatives at arbitrary points
    z = np.linspace(-0.1 * l, 1.1 * l, 7)
    for d in range(4):
        ref = np.stack([P.polyval(z, P.polyder(c, d)) for c in N], axis=-1)
        np.testing.assert_allclose(el.hermite_shape(z, l, d), ref, rtol=1e-12, atol=1e-12)
    # mass-weighted integrals for an element starting at x0
    x0 = 0.4
    S0, S1 = el.mass_integrals(rho, l, x0)
    np.testing.assert_allclose(S0, [rho * integral(c, l) for c in N], rtol=1e-12)
    np.testing.assert_allclose(
        S1, [rho * integral(P.polymul([x0, 1.0], c), l) for c in N], rtol=1e-12
    )
    # axial element
    np.testing.assert_allclose(
        el.axial_mass(rho, l), rho * np.array([[l / 3, l / 6], [l / 6, l / 3]])
    )
    np.testing.assert_allclose(el.axial_stiffness(EI, l) @ [1.0, 1.0], 0.0, atol=1e-12)


def test_rigid_modes_and_total_mass():
    L, rho, n = 1.7, 3.0, 5
    b = el.assemble_beam(n, L, rho, EI=2.0, EA=50.0)
    x = b.node_x
    translation = np.zeros(2 * (n + 1))
    translation[0::2] = 1.0
    rotation = np.zeros(2 * (n + 1))
    rotation[0::2], rotation[1::2] = x, 1.0
    for mode in (translation, rotation):
        assert abs(mode @ b.K @ mode) < 1e-9  # no strain energy
        np.testing.assert_allclose(b.K @ mode, 0.0, atol=1e-9)
    assert translation @ b.M @ translation == pytest.approx(rho * L, rel=1e-13)
    assert rotation @ b.M @ rotation == pytest.approx(
        rho * L**3 / 3, rel=1e-13
    )  # inertia about x=0
    assert b.S0 @ translation == pytest.approx(rho * L, rel=1e-13)
    assert b.S1 @ translation == pytest.approx(rho * L**2 / 2, rel=1e-13)
    assert b.S1 @ rotation == pytest.approx(rho * L**3 / 3, rel=1e-13)
    ones = np.ones(n + 1)
    assert ones @ b.M_axial @ ones == pytest.approx(rho * L, rel=1e-13)
    np.testing.assert_allclose(b.K_axial @ ones, 0.0, atol=1e-10)


def cantilever_roots() -> np.ndarray:
    """beta L of a clamped-free beam from cos x cosh x = -1."""

    def f(x):
        return np.cos(x) * np.cosh(x) + 1.0

    return np.array([brentq(f, a, b, xtol=1e-14) for a, b in [(1, 3), (4, 6), (7, 9)]])


def test_cantilever_frequencies_converge_at_fourth_order():
    roots = cantilever_roots()
    np.testing.assert_allclose(roots, [1.87510, 4.69409, 7.85476], atol=1e-5)
    L, rho, EI = 1.3, 2.0, 5.0
    exact = roots**2 * np.sqrt(EI / (rho * L**4))
    errors = []
    for n in (2, 4, 8, 16):
        b = el.assemble_beam(n, L, rho, EI)
        w2 = sl.eigh(b.K[2:, 2:], b.M[2:, 2:], eigvals_only=True)[:3]
        errors.append(w2 / exact**2 - 1.0)
    errors = np.array(errors)
    assert np.all(errors > 0)  # consistent mass + conforming elements: upper bounds
    orders = np.log2(errors[:-1] / errors[1:])
    assert np.all((orders[1:] > 3.5) & (orders[1:] < 4.5)), orders
    assert np.all(np.abs(errors[-1]) < 1e-4)


@pytest.mark.parametrize("n", [1, 3, 8])
def test_static_tip_load_is_exact(n):
    L, EI, Pt = 2.0, 3.0, 0.7
    b = el.assemble_beam(n, L, 1.0, EI)
    f = np.zeros(2 * (n + 1))
    f[-2] = Pt
    q = np.linalg.solve(b.K[2:, 2:], f[2:])
    assert q[-2] == pytest.approx(Pt * L**3 / (3 * EI), rel=1e-12)
    assert q[-1] == pytest.approx(Pt * L**2 / (2 * EI), rel=1e-12)
    # deflection between nodes is cubic in each element and exact too: w(x) = P x^2 (3L - x) / (6
    # EI)
    qf = np.concatenate([[0.0, 0.0], q])
    for x in (0.31 * L, 0.77 * L):
        row = el.interpolation_row(x, n, L)
        assert row @ qf == pytest.approx(Pt * x**2 * (3 * L - x) / (6 * EI), rel=1e-12)


def test_buckling_loads_converge_to_euler():
    L, EI = 1.5, 2.0
    for support, exact in (
        ("pinned", np.pi**2 * EI / L**2),
        ("cantilever", np.pi**2 * EI / (4 * L**2)),
    ):
        errs = []
        for n in (2, 4, 8, 16):
            b = el.assemble_beam(n, L, 1.0, EI)
            G = el.assemble_geometric_stiffness(n, L, np.ones(n + 1))  # unit tension
            keep = np.arange(2 * (n + 1))
            fixed = [0, 2 * n] if support == "pinned" else [0, 1]
            keep = np.setdiff1d(keep, fixed)
            # (K - P G) v = 0 for a compressive load P
            Pcr = sl.eigh(b.K[np.ix_(keep, keep)], G[np.ix_(keep, keep)], eigvals_only=True)[0]
            errs.append(Pcr / exact - 1.0)
        errs = np.array(errs)
        orders = np.log2(errs[:-1] / errs[1:])
        assert np.all(errs > 0) and errs[-1] < 1e-5 and np.all(orders[1:] > 3.5), (errs, orders)


def test_column_under_own_weight_linear_axial_force():
    """Greenhill: clamped base, free top, compression q (L - x): q_cr L^3 / EI = 9/4 j^2,
    J_{-1/3}(j) = 0."""
    j = brentq(lambda x: jv(-1.0 / 3.0, x), 1.0, 2.5, xtol=1e-14)
    exact = 2.25 * j**2  # 7.837...
    L, EI, n = 1.0, 1.0, 16
    b = el.assemble_beam(n, L, 1.0, EI)
    G_nodal = el.assemble_geometric_stiffness(n, L, -(L - b.node_x))
    G_call = el.assemble_geometric_stiffness(n, L, lambda x: -(L - x))
    np.testing.assert_allclose(G_nodal, G_call, rtol=1e-12, atol=1e-12)
    qcr = sl.eigh(b.K[2:, 2:], -G_nodal[2:, 2:], eigvals_only=True)
    assert qcr[qcr > 0].min() == pytest.approx(exact, rel=2e-5)


def test_rotating_cantilever_quadratic_axial_force():
    """Centrifugal stiffening, F = rho Omega^2 (L^2 - x^2)/2; Wright et al. (1982): 3.6816,
    22.181 at Omega = 1."""
    n = 16
    b = el.assemble_beam(n, 1.0, 1.0, 1.0)
    G = el.assemble_geometric_stiffness(n, 1.0, lambda x: 0.5 * (1.0 - x**2))
    w = np.sqrt(sl.eigh(b.K[2:, 2:] + G[2:, 2:], b.M[2:, 2:], eigvals_only=True)[:2])
    np.testing.assert_allclose(w, [3.6816, 22.181], rtol=1e-4)


def test_locate_and_interpolation_rows():
    n, L = 4, 1.0
    assert el.locate(0.25, n, L) == (1, 0.0)
    assert el.locate(1.0, n, L)[0] == 3
    with pytest.raises(ValueError, match="outside"):
        el.locate(1.1, n, L)
    q = np.random.default_rng(0).normal(size=2 * (n + 1))
    for k in range(n + 1):  # nodal values and slopes reproduced, C1 across nodes
        x = k * L / n
        assert el.interpolation_row(x, n, L) @ q == pytest.approx(q[2 * k], abs=1e-13)
        assert el.interpolation_row(x, n, L, 1) @ q == pytest.approx(q[2 * k + 1], abs=1e-12)
    with pytest.raises(ValueError):
        el.hermite_shape(0.1, 0.0)
