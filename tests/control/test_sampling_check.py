"""The design warning: undamped elastic modes and modes near a multiple of half the sample rate.

The rule's distance is checked against a closed form, and the flagged modes against the
sampled system itself: a mode ``d`` from a multiple of ``fs/2`` has sampled eigenvalues at
angle ``pi (k +- d)``, so ``|sin(angle)| = sin(pi d)`` (computed here from ``expm(A T)``,
not from the diagnosis).
"""

import dataclasses
import warnings

import numpy as np
import pytest
import scipy.linalg
from support import scene_arm

import flexctrl as fc
from flexctrl.control.sampling_check import ALIAS_TOLERANCE, alias_distance, sampling_diagnosis
from flexctrl.linear import Linearizer

TARGET = np.radians([30.0, 0.0, 0.0])


def arm(zeta: float):
    """The horizontal 2 kg arm, two modes per link, damping ratio ``zeta`` on every link."""
    return scene_arm(2.0, start_deg=None, zeta=zeta)


@pytest.fixture(scope="module")
def damped():
    return arm(0.005)


@pytest.fixture(scope="module")
def undamped():
    return arm(0.0)


def sampled_angle_sines(model, op, T: float) -> np.ndarray:
    """``|sin(arg z)|`` of the sampled elastic eigenvalues ``z`` of ``expm(A T)`` (|z| < 1)."""
    A = Linearizer(model, ("joints",)).matrices(op)[0]
    z = np.linalg.eigvals(scipy.linalg.expm(A * T))
    elastic = z[np.abs(z) < 1.0 - 1e-6]  # the rigid double integrators sit at z = 1
    return np.abs(elastic.imag) / np.abs(elastic)


def test_alias_distance_closed_form():
    T = 0.002  # fs/2 = 250 Hz
    d, k = alias_distance([250.0, 500.0, 625.0, 62.5, 740.0], T)
    np.testing.assert_allclose(d, [0.0, 0.0, 0.5, 0.75, 0.04], atol=1e-12)
    np.testing.assert_array_equal(k, [1, 2, 2, 1, 3])


@pytest.mark.parametrize("T, tolerance, flagged", [(0.0085, 0.04, True), (0.0025, 0.03, False)])
def test_rule_agrees_with_the_sampled_eigenvalues(damped, T, tolerance, flagged):
    """A flagged mode is one whose sampled pair lies within ``tolerance pi`` of the real axis."""
    op = fc.equilibrium(damped, TARGET)
    sines = sampled_angle_sines(damped, op, T)
    diagnosis = sampling_diagnosis(damped, op, T, tolerance=tolerance)
    assert bool(np.any(sines < np.sin(np.pi * tolerance))) == flagged
    assert bool(np.any(diagnosis.near_alias)) == flagged
    np.testing.assert_allclose(
        np.sort(np.sin(np.pi * diagnosis.distance)), np.sort(np.unique(sines.round(12))), rtol=1e-6
    )


def test_flags_the_235_hz_mode_of_the_undamped_arm_at_8_5_ms(undamped):
    op = fc.equilibrium(undamped, TARGET)
    diagnosis = sampling_diagnosis(undamped, op, 0.0085)
    assert diagnosis.undamped.all() and diagnosis.undamped.size == 6
    near = diagnosis.frequency_hz[diagnosis.near_alias]
    assert near.size == 1 and abs(near[0] - 2 / 0.0085) < 0.03 * 0.5 / 0.0085
    assert diagnosis.multiple[diagnosis.near_alias][0] == 4  # 4 x fs/2 = 2 fs
    sines = sampled_angle_sines(arm(1e-3), op, 0.0085)  # lightly damped: |z| < 1
    assert np.min(sines) < np.sin(np.pi * ALIAS_TOLERANCE)


def test_design_warns_in_one_line(undamped):
    op = fc.equilibrium(undamped, TARGET)
    with pytest.warns(fc.DesignWarning) as caught:
        ctrl = fc.design(undamped, op, fc.load_controller("controllers/lqr.toml"))
    (record,) = [w for w in caught if issubclass(w.category, fc.DesignWarning)]
    text = str(record.message)
    assert "\n" not in text
    assert "undamped" in text and "235.0 Hz" in text and "8.5 ms" in text
    assert ctrl.design_diagnosis is not None and ctrl.design_diagnosis.flagged


def test_design_is_quiet_on_a_clean_case(damped):
    """Damped links and a 2.5 ms sample time: every mode over 15 % of fs/2 from a multiple."""
    op = fc.equilibrium(damped, TARGET)
    settings = dataclasses.replace(fc.load_controller("controllers/lqr.toml"), sample_time=0.0025)
    with warnings.catch_warnings():
        warnings.simplefilter("error", fc.DesignWarning)
        ctrl = fc.design(damped, op, settings)
    assert ctrl.design_diagnosis is None
    assert sampling_diagnosis(damped, op, 0.0025).distance.min() > 0.15


def test_a_rigid_model_has_nothing_to_flag():
    rigid = fc.load_model("models/subedi3link.toml", fidelity="rigid", gravity=[0.0, 0.0])
    diagnosis = sampling_diagnosis(rigid, fc.equilibrium(rigid, TARGET), 0.0085)
    assert diagnosis.frequency_hz.size == 0 and not diagnosis.flagged
