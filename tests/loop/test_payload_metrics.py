"""The payload-estimate metrics, from traces whose answers are known by construction."""

from __future__ import annotations

import math

import numpy as np

from flexctrl.loop.metrics import METRICS, UNITS, payload_metrics


def test_an_estimate_that_never_settles_has_no_time():
    t = np.linspace(0.0, 2.0, 21)
    m = payload_metrics({"time": t, "mean": np.full(t.size, 1.5)}, 1.0)
    assert m["payload_estimate_error"] == 0.5 and math.isnan(m["payload_estimate_time"])


def test_the_time_is_when_the_estimate_enters_the_band_for_good():
    t = np.linspace(0.0, 2.0, 21)
    mean = np.where(t < 0.5, 3.0, 1.1)
    mean[12] = 1.5  # out again at 1.2 s
    m = payload_metrics({"time": t, "mean": mean}, 1.0)
    assert m["payload_estimate_time"] == t[13]
    assert abs(m["payload_estimate_error"] - 0.1) < 1e-12


def test_a_changing_payload_is_judged_against_its_own_truth():
    t = np.linspace(0.0, 4.0, 41)
    truth = lambda time: np.where(time < 2.0, 0.0, 4.0)  # noqa: E731
    mean = np.where(t < 2.5, 0.0, 4.0)
    m = payload_metrics({"time": t, "mean": mean}, truth)
    assert m["payload_estimate_time"] == 2.5 and m["payload_estimate_error"] == 0.0


def test_they_are_metrics_with_units():
    for name, unit in (("payload_estimate_error", "kg"), ("payload_estimate_time", "s")):
        assert name in METRICS and UNITS[name] == unit
