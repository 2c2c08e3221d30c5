"""Beam sliding over two bilateral supports (flexctrl.dynamics.fem.sliding_beam)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sl
from scipy.interpolate import CubicHermiteSpline

from flexctrl.dynamics.fem.sliding_beam import (
    FAST_PULL,
    FAST_PUSH,
    SLOW_PUSH,
    SlidingBeamModel,
    simulate_sliding_beam,
)

CASES = (SLOW_PUSH, FAST_PUSH, FAST_PULL)


def test_prescribed_motion_eq57_and_geometry():
    for case in CASES:
        t = np.linspace(0.0, 1.2 * case.T, 601)
        W = case.W(t)
        assert W[0] == pytest.approx(case.C1) and case.W(case.T) == pytest.approx(case.C1 - case.C2)
        assert np.all(W[t > case.T] == case.W(case.T))  # held after T
        eps = 1e-6
        tt = t[(t > eps) & (t < case.T - eps)]
        np.testing.assert_allclose(
            case.Wd(tt), (case.W(tt + eps) - case.W(tt - eps)) / (2 * eps), atol=1e-7
        )
        np.testing.assert_allclose(
            case.Wdd(tt), (case.Wd(tt + eps) - case.Wd(tt - eps)) / (2 * eps), atol=1e-5
        )
        assert abs(case.C2) / case.T * 2 == pytest.approx(
            np.abs(case.Wd(t)).max(), rel=1e-4
        )  # peak speed
    # push: long overhang (0.725 m) at H initially; supports at x = 0.025 and 0.275 m from E
    xs, _, _ = SlidingBeamModel(FAST_PUSH).support_positions(0.0)
    np.testing.assert_allclose(xs, [0.025, 0.275])
    xs, _, _ = SlidingBeamModel(FAST_PULL).support_positions(0.0)
    np.testing.assert_allclose(xs, [0.725, 0.975])


def closed_form_static(x, xs1, xs2, L=1.0):
    """Free-free beam on two simple supports under a uniform load (EI = p = 1), by statics."""
    # EI w'' = x^2/2 - R1 <x - xs1> - R2 <x - xs2>; w''(L) = 0 and w'''(L) = 0 fix R1, R2.
    R1, R2 = np.linalg.solve([[1.0, 1.0], [L - xs1, L - xs2]], [L, L**2 / 2])

    def part(z):
        return (
            z**4 / 24 - R1 * np.maximum(z - xs1, 0) ** 3 / 6 - R2 * np.maximum(z - xs2, 0) ** 3 / 6
        )

    c1 = -(part(xs2) - part(xs1)) / (xs2 - xs1)
    c0 = -part(xs1) - c1 * xs1
    return part(x) + c0 + c1 * x


@pytest.mark.parametrize("case", [FAST_PUSH, FAST_PULL])
def test_initial_shape_is_scaled_static_deflection(case):
    model = SlidingBeamModel(case, n_elements=40)  # supports on nodes: Hermite nodal values exact
    q0 = model.initial_shape()
    xs, _, _ = model.support_positions(0.0)
    x = np.linspace(0.0, 1.0, 41)
    w = closed_form_static(x, *xs)
    w *= 0.01 / (w[-1] if case.tracked_end == "H" else w[0])
    np.testing.assert_allclose(q0[0::2], w, atol=1e-12)
    coarse = SlidingBeamModel(case, n_elements=4).initial_shape()  # supports inside elements
    np.testing.assert_allclose(coarse[0::2], w[::10], atol=3e-4)


def test_constraint_rows_switch_elements_and_h_matches_finite_differences():
    model = SlidingBeamModel(FAST_PUSH, n_elements=4)
    prob = model.problem()
    rng = np.random.default_rng(1)
    q, v, a = (rng.normal(size=model.ndof) for _ in range(3))
    x = np.linspace(0.0, 1.0, 5)
    for t in (0.1, 0.3, 0.45):
        xs, _, _ = model.support_positions(t)
        spl = CubicHermiteSpline(x, q[0::2], q[1::2])
        np.testing.assert_allclose(prob.phi(q, t), spl(xs), atol=1e-13)
        for k, xk in enumerate(xs):  # row lives on the 4 dofs of the element holding x_k
            j = min(int(xk // 0.25), 3)
            assert set(np.flatnonzero(prob.phi_q(q, t)[k])) <= set(range(2 * j, 2 * j + 4))

        # Phi along q(s) = q + (s-t) v + (s-t)^2 a/2: Phidot and Phidd by central differences
        def qs(s, t=t):
            return q + (s - t) * v + 0.5 * (s - t) ** 2 * a

        e = 1e-4

        def ph(s, qs=qs):
            return prob.phi(qs(s), s)

        pd = (ph(t + e / 100) - ph(t - e / 100)) / (2 * e / 100)
        pdd = (ph(t + e) - 2 * ph(t) + ph(t - e)) / e**2
        np.testing.assert_allclose(
            prob.phi_q(q, t) @ v + prob.phi_t(q, t), pd, rtol=1e-6, atol=1e-6
        )
        np.testing.assert_allclose(
            prob.phi_q(q, t) @ a - prob.h(q, v, t), pdd, rtol=1e-4, atol=1e-4
        )
    assert set(np.flatnonzero(prob.phi_q(q, 0.0)[1])) == set(range(2, 6))  # x = 0.275: element 1
    assert set(np.flatnonzero(prob.phi_q(q, 0.7)[1])) == set(range(6, 10))  # x = 0.975: element 3


def test_axial_force_profile_and_sign():
    model = SlidingBeamModel(FAST_PUSH, n_elements=4)
    x = np.linspace(0.0, 1.0, 5)
    slope1 = np.zeros(model.ndof)
    slope1[0::2], slope1[1::2] = x, 1.0  # w' = 1: q G q = int F dx = rho L^2 / 2 per unit Wdd
    assert slope1 @ model.G @ slope1 == pytest.approx(0.5, rel=1e-12)
    slopex = np.zeros(model.ndof)
    slopex[0::2], slopex[1::2] = x**2 / 2, x  # w' = x: int rho x * x^2 dx = 1/4
    assert slopex @ model.G @ slopex == pytest.approx(0.25, rel=1e-12)
    assert sl.eigvalsh(model.G).min() > -1e-12  # F >= 0 per unit Wdd (drive at H, free end E)

    def lowest_omega2(case, t, on):
        m = SlidingBeamModel(case, 4, axial_shortening=on)
        N = sl.null_space(m.problem().phi_q(None, t))
        return sl.eigh(N.T @ m.stiffness(t) @ N, N.T @ m.M @ N, eigvals_only=True)[0]

    t = FAST_PUSH.T / 4  # accelerating: push compresses (softer), pull stretches (stiffer)
    assert FAST_PUSH.Wdd(t) < 0 < FAST_PULL.Wdd(t)
    # at peak push acceleration the frozen-time beam is even beyond its buckling load
    assert lowest_omega2(FAST_PUSH, t, True) < 0.0 < lowest_omega2(FAST_PUSH, t, False)
    assert lowest_omega2(FAST_PULL, t, True) > 1.3 * lowest_omega2(FAST_PULL, t, False)


@pytest.fixture(scope="module")
def runs():
    out = {}
    for case in CASES:
        out[case.name, True] = simulate_sliding_beam(case, 4, dt=1e-3)
    for case in (FAST_PUSH, FAST_PULL):
        out[case.name, False] = simulate_sliding_beam(case, 4, dt=1e-3, axial_shortening=False)
    return out


def test_push_and_pull_mirror_without_axial_shortening(runs):
    """Mirror x -> L - x maps the pull (E tracked) onto the push (H tracked): identical tips."""
    push, pull = runs["fast push", False], runs["fast pull", False]
    np.testing.assert_array_equal(push.t, pull.t)
    assert np.abs(push.tip_y).max() == pytest.approx(0.01)
    np.testing.assert_allclose(push.tip_y, pull.tip_y, rtol=0, atol=1e-12)
    # nodal deflections are mirror images too
    np.testing.assert_allclose(push.q[:, 0::2], pull.q[:, -2::-2], rtol=0, atol=1e-12)


def test_axial_shortening_separates_push_and_pull(runs):
    push, pull = runs["fast push", True], runs["fast pull", True]
    diff = np.abs(push.tip_y - pull.tip_y)
    assert diff.max() > 5e-3  # half the initial 0.01 m tip deflection
    assert np.abs(push.tip_y - runs["fast push", False].tip_y).max() > 2e-3
    assert push.tip_y[0] == pytest.approx(0.01) and pull.tip_y[0] == pytest.approx(0.01)


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_constraint_violation_bounded(runs, case):
    res = runs[case.name, True]
    assert res.t[-1] == pytest.approx(max(case.T, 1.0))
    assert res.phi_violation.max() < 2e-5  # m, vs 1e-2 m deflections
    assert res.phidot_violation.max() < 1e-3  # m/s
    assert np.all(np.isfinite(res.tip_y)) and np.abs(res.tip_y).max() < 0.03


def test_refinement_converges():
    ref = simulate_sliding_beam(FAST_PUSH, 32, dt=1e-3)
    maxs, rmss = [], []
    for n in (4, 8, 16):
        d = simulate_sliding_beam(FAST_PUSH, n, dt=1e-3).tip_y - ref.tip_y
        maxs.append(np.abs(d).max())
        rmss.append(np.sqrt(np.mean(d**2)))
    assert maxs[0] > maxs[1] > maxs[2] and rmss[0] > rmss[1] > rmss[2], (maxs, rmss)
    assert maxs[0] < 5e-3 and maxs[2] < 2.5e-4 and rmss[2] < 5e-5
