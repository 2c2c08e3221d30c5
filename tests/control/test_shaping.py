"""Input shaping: analytic impulse trains; no residual vibration of a simulated oscillator."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from flexctrl import linear as L
from flexctrl.control import design
from flexctrl.control.nmpc.controller import interval_functions
from flexctrl.control.shaping import Shaper, design_shaper, residual_vibration, zv, zvd
from flexctrl.spec.controller_settings import ShapedSettings


@pytest.mark.parametrize("f, zeta", [(2.0, 0.0), (5.3, 0.05), (0.7, 0.3)])
def test_zv_and_zvd_match_the_analytic_formulas(f, zeta):
    K = math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2))
    Td = 1.0 / (f * math.sqrt(1 - zeta**2))  # damped period
    s = zv(f, zeta)
    np.testing.assert_allclose(s.amplitudes, [1 / (1 + K), K / (1 + K)], rtol=1e-14)
    np.testing.assert_allclose(s.times, [0.0, Td / 2], rtol=1e-14)
    s = zvd(f, zeta)
    np.testing.assert_allclose(
        s.amplitudes, [1 / (1 + K) ** 2, 2 * K / (1 + K) ** 2, K**2 / (1 + K) ** 2], rtol=1e-14
    )
    np.testing.assert_allclose(s.times, [0.0, Td / 2, Td], rtol=1e-14)
    assert s.amplitudes.sum() == pytest.approx(1.0)


def oscillator_after(shaper: Shaper, f: float, zeta: float) -> np.ndarray:
    """State (x - 1, xd) of x'' + 2 zeta w x' + w^2 x = w^2 r(t) right after the last impulse of the
    shaped unit step.

    Exact: the reference is constant between impulses, so each segment is a matrix exponential.
    """
    w = 2 * math.pi * f
    A = np.array([[0.0, 1.0], [-w * w, -2 * zeta * w]])
    x, r = np.zeros(2), 0.0
    times = np.r_[shaper.times, shaper.times[-1]]
    for i, a in enumerate(shaper.amplitudes):
        r += a  # the step of this impulse
        span = times[i + 1] - times[i]
        x = scipy.linalg.expm(A * span) @ (x - [r, 0.0]) + [r, 0.0]
    return x - [1.0, 0.0]


def amplitude(state: np.ndarray, f: float, zeta: float) -> float:
    """Amplitude of the free vibration from ``state`` (energy-equivalent, in units of x)."""
    w = 2 * math.pi * f
    return float(math.hypot(state[0], state[1] / w))


@pytest.mark.parametrize("kind", ["zv", "zvd"])
@pytest.mark.parametrize("f, zeta", [(3.0, 0.0), (3.0, 0.1), (12.0, 0.02)])
def test_shaped_step_leaves_no_residual_vibration(kind, f, zeta):
    shaper = {"zv": zv, "zvd": zvd}[kind](f, zeta)
    residual = amplitude(oscillator_after(shaper, f, zeta), f, zeta)
    unshaped = amplitude(
        oscillator_after(Shaper(np.array([1.0]), np.array([0.0])), f, zeta), f, zeta
    )
    assert unshaped == pytest.approx(1.0)
    assert residual < 1e-10
    assert residual_vibration(shaper, f, zeta) < 1e-12


def test_zvd_is_more_robust_than_zv_to_frequency_error():
    f, zeta = 4.0, 0.02
    for error in (0.9, 1.15):
        actual = f * error
        v_zv = amplitude(oscillator_after(zv(f, zeta), actual, zeta), actual, zeta)
        v_zvd = amplitude(oscillator_after(zvd(f, zeta), actual, zeta), actual, zeta)
        assert v_zvd < 0.5 * v_zv
        # the analytic residual ratio (shaped / unshaped vibration) matches the simulated step,
        # whose unshaped residual amplitude is 1
        assert residual_vibration(zv(f, zeta), actual, zeta) == pytest.approx(v_zv, rel=0.05)


def test_convolved_shapers_cancel_both_modes():
    shaper = design_shaper([(2.0, 0.01), (7.5, 0.03)], "zv")
    assert shaper.amplitudes.size == 4 and shaper.amplitudes.sum() == pytest.approx(1.0)
    for f, zeta in [(2.0, 0.01), (7.5, 0.03)]:
        assert amplitude(oscillator_after(shaper, f, zeta), f, zeta) < 1e-10
    assert design_shaper([], "zvd").times.tolist() == [0.0]


def test_shaped_controller_reference_steps_through_the_impulses(damped3):
    op = L.equilibrium(damped3, np.radians([80.0, -10.0, -10.0]))
    ctrl = design(damped3, op, ShapedSettings(shaper="zvd"))
    f, zeta = ctrl.modes[0]
    assert 0.1 < f < 50.0 and 0 <= zeta < 0.3
    assert ctrl.shaper.duration == pytest.approx(1.0 / (f * math.sqrt(1 - zeta**2)))
    ctrl.reset()
    q0 = op.joints + np.radians([5.0, -5.0, 5.0])
    ref = ctrl.reference_terms(1.0, q0)[0]  # the first call fixes the start
    np.testing.assert_allclose(ref, q0 + ctrl.shaper.amplitudes[0] * (op.joints - q0))
    mid = ctrl.reference_terms(1.0 + 0.5 * (ctrl.shaper.times[1] + ctrl.shaper.times[2]), q0)[0]
    np.testing.assert_allclose(mid, q0 + ctrl.shaper.amplitudes[:2].sum() * (op.joints - q0))
    end = ctrl.reference_terms(1.0 + ctrl.shaper.duration + 1e-9, q0)[0]
    np.testing.assert_allclose(end, op.joints)


def test_locked_frequency_source_uses_the_locked_structure(damped3):
    op = L.equilibrium(damped3, np.radians([80.0, -10.0, -10.0]))
    ctrl = design(damped3, op, ShapedSettings(shaper="zv", modes=2, frequency_source="locked"))
    np.testing.assert_allclose([f for f, _ in ctrl.modes], L.locked_frequencies(damped3, op)[:2])


def test_shaped_move_deflects_the_links_less_than_the_unshaped_step(damped3):
    """The classical comparison on the nonlinear arm: the same PD, a step or a ZVD-shaped one."""
    op = L.equilibrium(damped3, np.radians([80.0, -10.0, -10.0]))
    F, _ = interval_functions(damped3, 0.001, 3, "frozen")
    start = L.equilibrium(damped3, np.radians([76.0, -8.0, -12.0]))
    static = np.array(damped3.functions["deflection"](op.q)[0], dtype=float).ravel()
    peak = {}
    for kind in ("none", "zvd"):
        ctrl = design(damped3, op, ShapedSettings(shaper=kind, modes=2))
        ctrl.reset()
        x = start.x.copy()
        worst = 0.0
        for k in range(1500):
            x = np.array(
                F(x, ctrl.step(0.001 * k, ctrl.sensors.measure(x, ctrl.u_previous))), dtype=float
            ).ravel()
            w = np.array(damped3.functions["deflection"](x[:9])[0], dtype=float).ravel()
            worst = max(worst, float(np.max(np.abs(w - static))))
        peak[kind] = worst
    assert peak["zvd"] < 0.8 * peak["none"]
