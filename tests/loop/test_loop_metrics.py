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


def _run(t_end: float, final_error: float, diverged_at: float | None = None):
    """A 2-joint run whose tip error decays from 50 mm to ``final_error`` (m) by t = 2 s, stopped
    at ``t_end`` (s) by a divergence at ``diverged_at`` when given."""
    from types import SimpleNamespace

    t = np.linspace(0.0, t_end, int(round(t_end / 1e-3)) + 1)
    err = final_error + (0.05 - final_error) * np.clip(1.0 - t / 2.0, 0.0, 1.0)
    divergence = None if diverged_at is None else {"time": diverged_at, "message": "test"}
    return SimpleNamespace(
        time=t,
        tip=np.stack([1.0 + err, np.zeros_like(t)], axis=1),
        deflections=np.zeros((t.size, 2)),
        inputs=np.ones((t.size, 2)),
        states=np.zeros((t.size, 4)),
        meta={"divergence": divergence},
    )


def _judged(trajectory, radius=None):
    from flexctrl.loop.metrics import run_metrics

    return run_metrics(
        trajectory,
        tip_target=(1.0, 0.0),
        reference_joints=np.zeros((trajectory.time.size, 2)),
        t_arrive=1.5,
        settle_allowance=1.0,
        band=1e-3,
        stable_band=0.01,
        torque_limits=(10.0, 10.0),
        controller_stats={},
        radius=radius,
    )


def test_a_run_stopped_before_its_window_has_empty_residuals_and_says_why():
    from flexctrl.loop.metrics import metric_notes

    trajectory = _run(0.364, 0.0, diverged_at=0.364)
    m = _judged(trajectory)
    assert math.isnan(m["tip_residual_rms"]) and math.isnan(m["tip_residual_peak"])
    assert math.isnan(m["settling_time"])
    assert m["stable"] == 0 and m["settled_within_band"] == 0 and m["settled"] == 0
    assert m["divergence_time"] == 0.364
    notes = metric_notes(m, trajectory.meta["divergence"], window_start=2.5, band=1e-3)
    assert set(notes) == {"tip_residual_rms", "tip_residual_peak", "settling_time"}
    assert (
        "diverged at 0.364 s, before its residual window opened at 2.5 s" in notes["settling_time"]
    )


def test_stable_means_stable_and_the_band_check_has_its_own_name():
    """A slow loop 16 mm off at the end: stable, not settled within the 10 mm band."""
    from flexctrl.loop.metrics import metric_notes

    slow = _judged(_run(4.0, 0.016))
    assert slow["stable"] == 1 and slow["settled_within_band"] == 0
    assert slow["final_tip_error"] == pytest.approx(0.016)
    assert math.isnan(slow["settling_time"]) and math.isnan(slow["divergence_time"])
    assert slow["tip_residual_rms"] == pytest.approx(0.016)  # measured: the run finished
    notes = metric_notes(slow, None, window_start=2.5, band=1e-3)
    assert notes == {
        "settling_time": "the tip error never stayed inside the 1 mm band to the end",
        "divergence_time": "the run did not diverge",
    }
    settled = _judged(_run(4.0, 0.0))
    assert settled["stable"] == settled["settled_within_band"] == settled["settled"] == 1
    assert settled["settling_time"] == pytest.approx(2.0 - 2.0 * 1e-3 / 0.05, abs=2e-3)
    # the linear verdict counts where there is one
    assert _judged(_run(4.0, 0.0), radius=1.02)["stable"] == 0
    assert _judged(_run(4.0, 0.0), radius=0.98)["stable"] == 1


def test_every_metric_knows_its_unit_and_better_direction():
    from flexctrl.loop.metrics import JOINT_METRICS, METRIC_INFO, METRICS, UNITS
    from flexctrl.study.column_units import lower_is_better

    # the payload metrics come from payload-aware controllers only (payload_metrics)
    keys = set(_judged(_run(4.0, 0.0), radius=0.5)) | {
        "payload_estimate_error",
        "payload_estimate_time",
    }
    assert keys == set(METRICS) | set(JOINT_METRICS) == set(METRIC_INFO) == set(UNITS)
    assert not lower_is_better("stable") and not lower_is_better("settled_within_band")
    assert lower_is_better("tip_residual_rms") and lower_is_better("peak_torque_2")
    assert lower_is_better("tip_error_rms")  # another executor's error: lower
