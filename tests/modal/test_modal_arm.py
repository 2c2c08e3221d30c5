"""Modal analysis of the Subedi three-link arm: Table 3, boundary values, lookup table, CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from flexctrl.cli import main
from flexctrl.modal.arm_modes import link_modes
from flexctrl.modal.boundary import boundary_values
from flexctrl.modal.identify import identify_hub_masses, table3_residuals
from flexctrl.modal.lookup import interpolation_error_hz, modal_lookup
from flexctrl.modal.paper_data import SUBEDI_TABLE3_HZ
from flexctrl.spec.arm import load_arm


@pytest.fixture(scope="module")
def arm(request):
    from support import MODEL

    return load_arm(MODEL)


def test_table3_all_twelve_frequencies_within_0p01_hz(arm):
    rows = table3_residuals(arm)
    assert len(rows) == 12
    for payload, link, mode, ref, model, residual in rows:
        assert abs(residual) < 0.01, (payload, link, mode, ref, model)


def test_link3_rows_need_no_hub_mass(arm):
    """Link 3 of Table 3 is independent of the identified hubs: zero hubs give the same rows."""
    stripped = arm.__class__(
        **{
            **arm.__dict__,
            "joints": tuple(j.__class__(**{**j.__dict__, "hub_mass": 0.0}) for j in arm.joints),
        }
    )
    for (_, _, _, _, model, res), (_, _, _, _, model0, _) in zip(
        table3_residuals(arm, (3,)), table3_residuals(stripped, (3,))
    ):
        assert model == pytest.approx(model0, abs=1e-12)
        assert abs(res) < 0.01


def test_identification_reproduces_the_masses_recorded_in_the_file(arm):
    fit = identify_hub_masses(arm)
    assert fit.hub_masses[2] == pytest.approx(arm.joints[1].hub_mass, abs=2e-3)
    assert fit.hub_masses[3] == pytest.approx(arm.joints[2].hub_mass, abs=2e-3)
    assert fit.max_abs_hz < 0.005  # inside Table 3's own rounding


def _eq69(arm, q2, q3, payload, projected):
    """Eqs 69-71 of Subedi et al. written out for three links (independent of boundary.py)."""
    l2, l3 = arm.links[1].length, arm.links[2].length
    ml2, ml3 = arm.links[1].mass, arm.links[2].mass
    Jl2, Jl3 = arm.links[1].inertia, arm.links[2].inertia
    mh2, mh3 = arm.joints[1].hub_mass, arm.joints[2].hub_mass
    Jh2, Jh3 = arm.joints[1].hub_inertia, arm.joints[2].hub_inertia
    Jp = arm.payload.inertia if payload > 0 else 0.0
    if projected:  # Eq 70 as printed
        d_l32_sq = (l2 + l3 / 2 * math.cos(q3)) ** 2
        d_p2_sq = (l2 + l3 * math.cos(q3)) ** 2
    else:  # law of cosines: full distance from joint 2
        d_l32_sq = l2**2 + (l3 / 2) ** 2 + l2 * l3 * math.cos(q3)
        d_p2_sq = l2**2 + l3**2 + 2 * l2 * l3 * math.cos(q3)
    J1 = (
        Jh2
        + Jl2
        + ml2 * (l2 / 2) ** 2
        + Jh3
        + mh3 * l2**2
        + Jl3
        + ml3 * d_l32_sq
        + Jp
        + payload * d_p2_sq
    )
    m1 = mh2 + ml2 + mh3 + ml3 + payload
    M1 = (
        ml2 * l2 / 2 * math.cos(q2)
        + mh3 * l2 * math.cos(q2)
        + ml3 * (l2 * math.cos(q2) + l3 / 2 * math.cos(q2 + q3))
        + payload * (l2 * math.cos(q2) + l3 * math.cos(q2 + q3))
    )
    J2 = Jh3 + Jl3 + ml3 * (l3 / 2) ** 2 + Jp + payload * l3**2
    m2 = mh3 + ml3 + payload
    M2 = (ml3 * l3 / 2 + payload * l3) * math.cos(q3)
    return (m1, J1, M1), (m2, J2, M2), (payload, Jp, 0.0)


@pytest.mark.parametrize("convention", ["exact", "paper"])
@pytest.mark.parametrize("payload", [0.0, 2.0])
def test_boundary_values_match_eqs_69_to_73(arm, convention, payload):
    loaded = arm.with_payload(payload)
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = np.array([rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-3, 3)])
        expected = _eq69(loaded, q[1], q[2], payload, projected=(convention == "paper"))
        for link in range(3):
            bv = boundary_values(loaded, q, link, convention)
            assert (float(bv.m), float(bv.J), float(bv.M)) == pytest.approx(
                expected[link], rel=1e-12, abs=1e-12
            )


def test_exact_and_paper_inertia_agree_only_at_0_and_180_degrees(arm):
    for q3 in (0.0, math.pi):
        q = np.array([0.0, 0.7, q3])
        assert float(boundary_values(arm, q, 0, "exact").J) == pytest.approx(
            float(boundary_values(arm, q, 0, "paper").J), rel=1e-12
        )
    q = np.array([0.0, 0.7, math.pi / 2])
    assert (
        float(boundary_values(arm, q, 0, "exact").J) - float(boundary_values(arm, q, 0, "paper").J)
        > 1.0
    )


def test_frequencies_fall_with_payload_and_link1_ignores_q1(arm):
    light, heavy = arm.with_payload(0.5), arm.with_payload(4.0)
    q = np.radians([30.0, 60.0, -45.0])
    for link in range(3):
        assert np.all(
            link_modes(heavy, q, link).frequency_hz < link_modes(light, q, link).frequency_hz
        )
    f_a = link_modes(arm, np.radians([0.0, 60.0, -45.0]), 0).frequency_hz
    f_b = link_modes(arm, np.radians([123.0, 60.0, -45.0]), 0).frequency_hz
    assert f_a == pytest.approx(f_b, rel=1e-12)


def test_lookup_table_interpolates_exact_solves(arm):
    table = modal_lookup(arm, 0, 2, step_deg=10.0)
    assert table.joints == (1, 2)
    assert interpolation_error_hz(arm, table, samples=40, seed=3) < 0.05
    # on grid points the spline reproduces the exact solve
    q = np.radians([0.0, 30.0, -60.0])
    exact = link_modes(arm, q, 0, 2)
    got = table.evaluate(q)
    assert got["omega"] == pytest.approx(exact.omega, rel=1e-9)
    assert np.abs(got["tip_deflection"]) == pytest.approx(np.abs(exact.tip_deflection), rel=1e-9)
    # wrapping: +-180 degrees are the same configuration
    assert table.evaluate(np.radians([0, 180.0, 20.0]))["omega"] == pytest.approx(
        table.evaluate(np.radians([0, -180.0, 20.0]))["omega"], rel=1e-9
    )


def test_lookup_is_differentiable_and_its_derivative_matches_finite_differences(arm):
    import casadi as ca

    table = modal_lookup(arm, 0, 2, step_deg=10.0)
    q = ca.SX.sym("q", 3)
    jac = ca.Function("j", [q], [ca.jacobian(table.function(q)[0], q)])
    q0 = np.radians([0.0, 37.0, 71.0])
    J = np.array(jac(q0))
    h = 1e-5
    for k in (1, 2):
        dq = np.zeros(3)
        dq[k] = h
        fd = (
            np.array(table.function(q0 + dq)[0]) - np.array(table.function(q0 - dq)[0])
        ).ravel() / (2 * h)
        assert J[:, k] == pytest.approx(fd, rel=1e-4, abs=1e-6)
    assert np.all(J[:, 0] == 0.0)


def test_lookup_cache_is_reused(arm, tmp_path, monkeypatch):
    monkeypatch.setenv("FLEXCTRL_CACHE", str(tmp_path))
    first = modal_lookup(arm, 1, 2, step_deg=30.0)
    assert first.build_time_s > 0.0 and list(tmp_path.rglob("*.npz"))
    second = modal_lookup(arm, 1, 2, step_deg=30.0)
    assert second.build_time_s == 0.0
    assert np.array_equal(second.values["omega"], first.values["omega"])


def test_modes_cli_json_interface(capsys, model_path):
    assert (
        main(
            [
                "modes",
                str(model_path),
                "--payload",
                "2",
                "--q",
                "0",
                "0",
                "0",
                "--n-modes",
                "2",
                "--json",
            ]
        )
        == 0
    )
    result = json.loads(capsys.readouterr().out)
    links = result["links"]
    assert [len(e["frequencies_hz"]) for e in links] == [2, 2, 2]
    for entry, table in zip(links, SUBEDI_TABLE3_HZ[2.0]):
        assert entry["frequencies_hz"] == sorted(entry["frequencies_hz"])
        assert entry["frequencies_hz"] == pytest.approx(table, abs=0.01)


def test_modes_cli_set_and_fidelity(capsys, model_path):
    assert (
        main(
            [
                "modes",
                str(model_path),
                "--q",
                "0",
                "0",
                "90",
                "--set",
                "boundary_inertia=paper",
                "--json",
            ]
        )
        == 0
    )
    paper = json.loads(capsys.readouterr().out)["links"][0]["frequencies_hz"]
    assert main(["modes", str(model_path), "--q", "0", "0", "90", "--json"]) == 0
    exact = json.loads(capsys.readouterr().out)["links"][0]["frequencies_hz"]
    assert paper[0] != pytest.approx(exact[0], rel=1e-3)
    assert main(["modes", str(model_path), "--fidelity", "amm:3", "--json"]) == 0
    assert [len(e["frequencies_hz"]) for e in json.loads(capsys.readouterr().out)["links"]] == [
        3,
        3,
        3,
    ]


@pytest.mark.parametrize(
    "argv, key",
    [
        (["--set", "links[1].EI=0"], "links[1].EI"),
        (["--set", "lnks[1].EI=3"], "lnks"),
        (["--payload", "-2"], "payload.mass"),
        (["--payload", "nan"], "payload.mass"),
        (["--q", "0", "0"], "q"),
        (["--n-modes", "7"], "--n-modes"),
        (["--fidelity", "amm:9"], "--fidelity"),
    ],
)
def test_modes_cli_bad_input_exits_nonzero_with_one_line_naming_the_key(
    capsys, model_path, argv, key
):
    assert main(["modes", str(model_path), *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert key in err


def test_a_link_index_outside_the_arm_names_both_counts():
    import flexctrl as fc
    from flexctrl.errors import SpecError

    arm = fc.load_arm("subedi3link")
    assert fc.link_modes(arm, None, 2).frequency_hz.size == arm.links[2].n_modes
    with pytest.raises(
        SpecError, match=r"value 3 is not a link of this 3-link arm; allowed: 0\.\.2"
    ):
        fc.link_modes(arm, None, 3)  # the third link as the files count it
    with pytest.raises(SpecError, match=r"links\[1\]\.\.links\[3\]"):
        fc.link_modes(arm, None, -1)
    with pytest.raises(SpecError, match="not a link index"):
        fc.link_modes(arm, None, 1.0)
