"""Loading and validation of model files: every error names file, key, value and what is allowed."""

from __future__ import annotations

import math
import re

import pytest
from support import MODEL

from flexctrl.errors import SpecError
from flexctrl.spec.arm import load_arm
from flexctrl.spec.fidelity import Fidelity, parse_fidelity
from flexctrl.spec.overrides import apply_overrides, parse_value


def test_subedi_model_loads_with_table_values(model_path):
    arm = load_arm(model_path)
    assert arm.n_links == 3
    # Table 2 lists link masses; rho * L must reproduce them (an independent column of the table).
    for link, table_mass in zip(arm.links, (2.9808, 1.7982, 1.1138)):
        assert link.mass == pytest.approx(table_mass, abs=1e-4)
    # Table 2's centroidal inertias equal m L^2 / 12 of a slender beam.
    for link in arm.links:
        assert link.inertia == pytest.approx(link.mass * link.length**2 / 12, rel=2e-3)
    assert arm.gravity == (0.0, -9.81)
    assert arm.configuration == (0.0, 0.0, 0.0)


def test_youngs_modulus_implied_by_table2_is_aluminium(model_path):
    arm = load_arm(model_path)
    for link in arm.links:
        youngs = link.EI / link.section.second_moment
        assert 66e9 < youngs < 72e9  # aluminium, ~69 GPa
        # rho from Table 2 equals the section area times aluminium density ~2700 kg/m^3
        assert link.mass_per_length / link.section.area == pytest.approx(2700, rel=0.01)


def _write(tmp_path, text):
    path = tmp_path / "arm.toml"
    path.write_text(text)
    return path


BASE = MODEL.read_text()


@pytest.mark.parametrize(
    "override, key, fragment",
    [
        ("links[2].EI=-5", "links[2].EI", "> 0"),
        ("links[1].length=0", "links[1].length", "> 0"),
        ("links[3].mass_per_length=nan", "links[3].mass_per_length", "finite"),
        ("links[1].inertia=-1", "links[1].inertia", ">= 0"),
        ("links[1].damping_ratio=-0.1", "links[1].damping_ratio", ">= 0"),
        ("links[1].n_modes=7", "links[1].n_modes", "0 to 6"),
        ("links[1].n_modes=1.5", "links[1].n_modes", "integer"),
        ("joints[2].hub_mass=-3", "joints[2].hub_mass", ">= 0"),
        ("joints[1].type=slider", "joints[1].type", "revolute"),
        ("payload.mass=inf", "payload.mass", "finite"),
        ("gravity=[0, 1, 2]", "gravity", "exactly 2"),
        ("boundary_inertia=papr", "boundary_inertia", "did you mean 'paper'"),
        ('links[1].EI="stiff"', "links[1].EI", "not a number"),
    ],
)
def test_bad_values_are_refused_with_file_key_value_and_allowed(
    model_path, override, key, fragment
):
    with pytest.raises(SpecError) as info:
        load_arm(model_path, overrides=[override])
    message = str(info.value)
    assert str(model_path) in message
    assert f"'{key}'" in message
    assert fragment in message
    assert "\n" not in message
    assert info.value.key == key


def test_misspelt_key_gets_a_suggestion(tmp_path):
    path = _write(tmp_path, BASE.replace("mass_per_length = 1.1988", "mass_per_lenght = 1.1988"))
    with pytest.raises(
        SpecError, match=r"links\[2\]\.mass_per_lenght': did you mean 'mass_per_length'"
    ):
        load_arm(path)


def test_missing_key_and_missing_file(tmp_path):
    path = _write(tmp_path, BASE.replace("EI = 7.0361e3", ""))
    with pytest.raises(SpecError, match=r"links\[2\]\.EI'.*missing"):
        load_arm(path)
    with pytest.raises(SpecError, match="file not found"):
        load_arm(tmp_path / "nope.toml")


def test_joint_count_must_match_links(tmp_path):
    text = BASE.split("[[joints]]")
    path = _write(tmp_path, "[[joints]]".join(text[:-1]))
    with pytest.raises(SpecError, match="one joint per link"):
        load_arm(path)


def test_invalid_toml_is_a_spec_error(tmp_path):
    with pytest.raises(SpecError, match="not valid TOML"):
        load_arm(_write(tmp_path, "links = [[["))


def test_overrides_parse_toml_values_and_fall_back_to_strings():
    assert parse_value("2") == 2 and parse_value("1e-4") == 1e-4 and parse_value("true") is True
    assert parse_value("[0, 90]") == [0, 90] and parse_value("paper") == "paper"
    doc = {"links": [{"EI": 1.0}, {"EI": 2.0}], "payload": {"mass": 1.0}}
    new = apply_overrides(doc, ["links[2].EI=5", "links.1.EI=4", "payload.mass=0"])
    assert new == {"links": [{"EI": 4}, {"EI": 5}], "payload": {"mass": 0}}
    assert doc["links"][0]["EI"] == 1.0  # original untouched
    with pytest.raises(SpecError, match="index 3 does not exist"):
        apply_overrides(doc, ["links[3].EI=1"])
    with pytest.raises(SpecError, match="KEY=VALUE"):
        apply_overrides(doc, ["links"])


def test_with_payload_and_configuration_checks(model_path):
    arm = load_arm(model_path)
    assert arm.with_payload(0.0).payload.effective_inertia == 0.0
    assert arm.with_payload(2.0).payload.effective_inertia == pytest.approx(3.2e-4)
    with pytest.raises(SpecError, match="payload"):
        arm.with_payload(-1.0)
    with pytest.raises(SpecError, match="expected 3"):
        arm.configuration_or_default([0.0, 1.0])
    q = arm.configuration_or_default([0.1, 0.2, math.pi])
    assert q.tolist() == [0.1, 0.2, math.pi]


@pytest.mark.parametrize(
    "text, expected",
    [
        ("rigid", Fidelity("rigid")),
        ("amm:2", Fidelity("amm", 2)),
        ("FEM:16", Fidelity("fem", 16)),
        ("auto", Fidelity("auto")),
        ("amm:0", Fidelity("amm", 0)),
    ],
)
def test_fidelity_spellings(text, expected):
    assert parse_fidelity(text) == expected
    assert parse_fidelity(str(expected)) == expected


@pytest.mark.parametrize("text", ["amm", "amm:7", "fem:0", "fem:x", "modal:2", "", "amm:-1", 3])
def test_bad_fidelity_lists_the_spellings(text):
    with pytest.raises(SpecError, match=re.escape("'rigid', 'amm:N'")):
        parse_fidelity(text)
