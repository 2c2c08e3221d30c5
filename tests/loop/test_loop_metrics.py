"""Closed-loop metrics against hand-computable signals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexctrl.loop.metrics import closed_loop_metrics, settling_time


def test_decaying_sinusoid_metrics_match_closed_forms():
    t = np.linspace(0.0, 10.0, 100001)
    amp, sigma, omega = 0.01, 0.8, 2 * np.pi * 3.0
    err = amp * np.exp(-sigma * t) * np.cos(omega * t)
    tip = np.stack([1.0 + err, np.zeros_like(t)], axis=1)
    m = closed_loop_metrics(
        t,
        tip,
        (1.0, 0.0),
        np.zeros((t.size, 1)),
        np.ones((t.size, 2)) * [2.0, -3.0],
        np.zeros((t.size, 2)),
        np.zeros((t.size, 2)),
        t_arrive=1.0,
        settle_allowance=1.0,
        band=1e-3,
    )
    window = t >= 2.0
    assert m["tip_residual_peak"] == pytest.approx(amp * math.exp(-sigma * 2.0), rel=1e-6)
    # RMS of a fast-decaying sinusoid: sqrt(mean(a^2 e^{-2 s t} cos^2)) ~ envelope / sqrt(2) average
    envelope = np.sqrt(np.mean((amp * np.exp(-sigma * t[window])) ** 2) / 2)
    assert m["tip_residual_rms"] == pytest.approx(envelope, rel=0.02)
    # settling: envelope hits 1 mm at ln(10)/sigma; the last excursion above the band is just before
    # that
    assert m["settling_time"] <= math.log(amp / 1e-3) / sigma + 1e-9
    assert m["settling_time"] > math.log(amp / 1e-3) / sigma - 1.0 / 3.0
    assert m["peak_torque"] == [2.0, 3.0] and m["rms_torque"] == [2.0, 3.0]


def test_never_settling_and_empty_window():
    t = np.linspace(0, 1, 11)
    err = np.full(11, 0.01)
    assert settling_time(t, err, 1e-3) == math.inf
    assert settling_time(t, err * 0, 1e-3) == 0.0
    with pytest.raises(ValueError, match="lengthen the scene's duration"):
        closed_loop_metrics(
            t,
            np.zeros((11, 2)),
            (0, 0),
            np.zeros((11, 1)),
            np.zeros((11, 1)),
            np.zeros((11, 1)),
            np.zeros((11, 1)),
            t_arrive=0.8,
            settle_allowance=0.5,
        )
