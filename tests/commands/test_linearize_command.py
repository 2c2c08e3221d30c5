"""flexctrl linearize: the JSON interface and cross-checks between model families."""

from __future__ import annotations

import json

import numpy as np
import pytest

from flexctrl.cli import main
from flexctrl.modal.arm_modes import link_modes
from flexctrl.spec.arm import load_arm


def _run(capsys, *argv):
    assert main(["linearize", *map(str, argv), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_locked_frequencies_agree_between_assumed_modes_and_finite_elements(capsys, model_path):
    # Without gravity: no axial preload, which the finite elements carry (geometric stiffness) and
    # the
    # assumed modes do not; then the lowest three modes of two independent discretisations agree.
    flat = ("--set", "gravity=[0.0, 0.0]")
    amm = _run(capsys, model_path, "--payload", 2, "--q", 0, 90, 0, "--locked", *flat)
    fem = _run(
        capsys,
        model_path,
        "--payload",
        2,
        "--q",
        0,
        90,
        0,
        "--locked",
        "--fidelity",
        "fem:4",
        *flat,
    )
    assert (
        amm["frequencies_hz"] == sorted(amm["frequencies_hz"]) and len(amm["frequencies_hz"]) == 6
    )
    assert amm["frequencies_hz"][:3] == pytest.approx(fem["frequencies_hz"][:3], rel=2e-3)
    # static deflection under gravity, straight arm (link axes normal to gravity): the same
    # equilibrium
    amm = _run(capsys, model_path, "--q", 0, 0, 0)
    fem = _run(capsys, model_path, "--q", 0, 0, 0, "--fidelity", "fem:4")
    assert amm["static_tip_deflections_m"] == pytest.approx(
        fem["static_tip_deflections_m"], rel=2e-3
    )
    assert amm["equilibrium_torque_Nm"] == pytest.approx(fem["equilibrium_torque_Nm"], rel=1e-3)


def test_whole_arm_locked_frequency_is_below_every_per_link_clamped_mass_frequency(
    capsys, model_path
):
    """The arm's lowest locked mode couples all links; each link's clamped-mass model treats the
    outboard as rigid,
    so it is stiffer: the arm's first frequency lies below every link's first frequency."""
    amm = _run(capsys, model_path, "--q", 0, 0, 0, "--locked", "--fidelity", "amm:3")
    arm = load_arm(model_path)
    per_link = [link_modes(arm, np.zeros(3), i, 1).frequency_hz[0] for i in range(3)]
    assert amm["frequencies_hz"][0] < min(per_link)


def test_bad_input(capsys, model_path):
    assert main(["linearize", str(model_path), "--fidelity", "amm:9"]) == 2
    assert "--fidelity" in capsys.readouterr().err
