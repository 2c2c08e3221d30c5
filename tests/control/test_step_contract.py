"""The step contract of every controller kind: a bad measurement never corrupts a controller.

A non-finite entry or a wrong length raises :class:`MeasurementError` naming the channel,
the value and the time, and the next valid measurement gives the torque of a controller
that never saw the bad one; with ``on_bad_measurement = "hold"`` the sample is predicted
through (the estimator's model, no correction) and counted.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from flexctrl import linear as L
from flexctrl.control import design
from flexctrl.errors import MeasurementError, SpecError
from flexctrl.spec.controller_settings import (
    EstimatorSettings,
    LQRSettings,
    MPCSettings,
    NMPCSettings,
    PDSettings,
    SensorSettings,
    ShapedSettings,
)
from flexctrl.spec.reference import Move

STRAIN = SensorSettings(outputs=("joints", "strain"), joints=1e-5, strain=1e-5)
KINDS = {
    "pd": PDSettings(sample_time=0.01),
    "shaped": ShapedSettings(pd=PDSettings(sample_time=0.01)),
    "lqr": LQRSettings(sample_time=0.01),
    "lqg": LQRSettings(
        sample_time=0.01, sensors=STRAIN, estimator=EstimatorSettings(torque_noise=1.0)
    ),
    "mpc": MPCSettings(sample_time=0.01, horizon=10),
    "mpc_lqg": MPCSettings(sample_time=0.01, horizon=10, sensors=STRAIN),
    "nmpc": NMPCSettings(compile=False, horizon=10, sample_time=0.02, deflection_limit=0.02),
}


def _hold(settings):
    if isinstance(settings, ShapedSettings):
        return dataclasses.replace(
            settings, pd=dataclasses.replace(settings.pd, on_bad_measurement="hold")
        )
    return dataclasses.replace(settings, on_bad_measurement="hold")


def _measurements(ctrl, op, count=4):
    """Measurements of the arm near ``op`` (0.02 rad off, moving): torques within the limits."""
    n = op.x.size
    x = op.x.copy()
    x[0] -= 0.02
    x[n // 2] = 0.03
    return [ctrl.sensors.evaluate(x + 0.001 * k, op.u) for k in range(count)]


@pytest.fixture(scope="module", params=sorted(KINDS))
def kind(request, onelink):
    model, op = onelink
    ctrl = design(model, op, KINDS[request.param])
    target = L.equilibrium(model, [0.6])
    ctrl.set_reference(Move(start=[0.4], target=target.joints, time=0.2))
    return request.param, ctrl, op


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_non_finite_entry_raises_and_leaves_the_controller_as_it_was(kind, bad):
    name, ctrl, op = kind
    ys = _measurements(ctrl, op)
    Ts = ctrl.sample_time
    ctrl.reset()
    clean = [ctrl.step(k * Ts, y) for k, y in enumerate(ys)]
    steps = ctrl.stats.summary()["steps"]
    ctrl.reset()
    for k in range(2):
        ctrl.step(k * Ts, ys[k])
    i = len(ys[2]) - 1
    broken = ys[2].copy()
    broken[i] = bad
    with pytest.raises(MeasurementError) as info:
        ctrl.step(2 * Ts, broken)
    error = info.value
    assert error.channel == ctrl.measurement_names[i] and error.t == pytest.approx(2 * Ts)
    assert repr(ctrl.measurement_names[i]) in str(error) and f"{2 * Ts:g} s" in str(error)
    assert isinstance(error, SpecError) and isinstance(error, ValueError)
    after = [ctrl.step(k * Ts, ys[k]) for k in (2, 3)]
    np.testing.assert_array_equal(after[0], clean[2], err_msg=name)
    np.testing.assert_array_equal(after[1], clean[3], err_msg=name)
    assert ctrl.stats.summary()["steps"] == steps


def test_a_wrong_length_raises_whatever_the_setting(kind):
    name, ctrl, op = kind
    held = design(ctrl.design_model, op, _hold(KINDS[name]))
    for c in (ctrl, held):
        c.reset()
        with pytest.raises(MeasurementError, match=f"expected {c.sensors.n_y}"):
            c.step(0.0, np.zeros(c.sensors.n_y + 1))
        assert c.stats.summary()["steps"] == 0


def test_hold_predicts_through_a_bad_sample_and_counts_it(kind):
    name, ctrl, op = kind
    ctrl = design(ctrl.design_model, op, _hold(KINDS[name]))
    ctrl.set_reference(None)
    ys = _measurements(ctrl, op)
    Ts = ctrl.sample_time
    ctrl.reset()
    with pytest.raises(MeasurementError, match="no valid measurement yet"):
        ctrl.step(0.0, np.full(ctrl.sensors.n_y, np.nan))
    u1 = [ctrl.step(k * Ts, ys[k]) for k in range(2)][-1]
    observer = getattr(ctrl, "observer", None)
    before = None if observer is None else observer.dx.copy()
    broken = ys[2].copy()
    broken[0] = np.nan
    u = ctrl.step(2 * Ts, broken)
    assert ctrl.stats.status["held"] == 1 and np.all(np.isfinite(u))
    if observer is None:  # PD and shaped: the previous torque
        np.testing.assert_array_equal(u, u1)
        return
    # the prediction alone, computed here from the discrete linearisation
    sysd = ctrl.plant.sysd
    expected = np.asarray(sysd.A) @ before + np.asarray(sysd.B) @ (u1 - op.u)
    np.testing.assert_allclose(observer.dx, expected, rtol=1e-12, atol=1e-14)
    if name == "lqr" or name == "lqg":  # the gain acts on the prediction
        u_law = op.u - ctrl.K @ expected
        assert np.all(np.abs(u_law) < ctrl.limits)
        np.testing.assert_allclose(u, u_law, rtol=1e-12, atol=1e-12)
    assert np.all(np.isfinite(ctrl.step(3 * Ts, ys[3])))
