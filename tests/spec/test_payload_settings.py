"""The [payload] table: its defaults, its grid, and every bad value refused by name."""

from __future__ import annotations

import math

import pytest

from flexctrl.errors import SpecError
from flexctrl.spec.controller_reader import controller_from_document, load_controller
from flexctrl.spec.payload_settings import PayloadSettings


def read(table: dict, kind: str = "lqr"):
    return controller_from_document({"kind": kind, "payload": table}, "c.toml")


def test_no_table_means_a_fixed_payload_controller():
    assert load_controller("lqr").payload is None
    assert load_controller("mpc").payload is None


def test_defaults_prior_is_the_ranges_middle_with_a_uniform_laws_std():
    s = read({"range": [1.0, 3.0]}).payload
    assert s.mean0 == pytest.approx(2.0)
    assert s.std0 == pytest.approx(2.0 / math.sqrt(12.0))
    assert s.grid_points() == (1.0, 1.25, 1.5, 1.75, 2.0, 2.25, 2.5, 2.75, 3.0)


def test_a_step_that_does_not_divide_the_range_ends_at_its_end():
    assert PayloadSettings(range=(0.0, 1.0), grid_step=0.4).grid_points() == (0.0, 0.4, 0.8, 1.0)


def test_rates_in_the_file_are_degrees():
    s = read({"excitation_rate_deg_s": 180.0}).payload
    assert s.excitation_rate == pytest.approx(math.pi)


@pytest.mark.parametrize(
    "table, key, words",
    [
        ({"range": [2.0, 2.0]}, "payload.range", "is empty"),
        ({"range": [-1.0, 2.0]}, "payload.range", "is negative"),
        ({"range": [4.0, 0.0]}, "payload.range", "is reversed"),
        ({"range": [0.0]}, "payload.range", "exactly 2"),
        ({"grid_step": 5.0}, "payload.grid_step", "wider than the range"),
        ({"grid": [0.0, 2.0]}, "payload.grid", "does not span"),
        ({"grid": [0.0, 3.0, 2.0, 4.0]}, "payload.grid", "not increasing"),
        ({"grid": [0.0, 4.0], "grid_step": 1.0}, "payload.grid", "one of grid or grid_step"),
        ({"prior_mean": 9.0}, "payload.prior_mean", "out of range"),
        ({"temper": 0.0}, "payload.temper", "out of range"),
        ({"excitation_rate_deg_s": -1.0}, "payload.excitation_rate_deg_s", "out of range"),
        ({"excitation_window": 0}, "payload.excitation_window", "not allowed"),
        ({"tempr": 0.1}, "payload.tempr", "did you mean 'temper'"),
        ({"rest_torque_noise": 0.01}, "payload.rest_torque_noise", "is given alone"),
        ({"identify_modal_force_noise": 0.01}, "payload.identify_modal_force_noise", "alone"),
        (
            {"rest_torque_noise": -1.0, "rest_modal_force_noise": 0.0},
            "payload.rest_torque_noise",
            ">= 0",
        ),
        ({"rest_delay": -0.1}, "payload.rest_delay", ">= 0"),
        ({"rest_dealy": 0.1}, "payload.rest_dealy", "did you mean 'rest_delay'"),
    ],
)
def test_bad_values_name_the_file_key_and_what_is_allowed(table, key, words):
    with pytest.raises(SpecError) as info:
        read(table)
    message = str(info.value)
    assert "c.toml" in message and f"'{key}'" in message and words in message


def test_the_mpc_file_takes_the_table_too():
    assert read({"range": [0.0, 2.0]}, "mpc").payload.range == (0.0, 2.0)


def test_the_pd_file_does_not():
    with pytest.raises(SpecError, match="unknown key"):
        read({"range": [0.0, 2.0]}, "pd")


def test_the_shipped_payload_aware_lqr_covers_0_to_4_kg():
    s = load_controller("lqr_payload").payload
    assert s.range == (0.0, 4.0) and s.grid_points()[1] == 0.25


def test_the_payload_aware_mpc_file_has_the_lqr_files_recipe():
    """Unconstrained, the MPC's first move is the LQR's only if both designs are the same."""
    m, q = load_controller("mpc_payload"), load_controller("lqr_payload")
    assert m.sample_time == q.sample_time and m.weights == q.weights
    assert m.sensors == q.sensors and m.estimator == q.estimator and m.payload == q.payload
    assert m.terminal == "dare"
