"""Damping on the arm's coupled modes (``damping_form = "modal"``) against the poles of the
linearisation, and the per-link form it stands beside."""

from __future__ import annotations

import numpy as np
import pytest
from support import MODEL, ROOT

import flexctrl as fc
from flexctrl.dynamics.build import ModelFamilyUnavailable
from flexctrl.errors import SpecError

POSE = np.radians([30.0, 0.0, 0.0])


def _pole_zetas(model, q) -> np.ndarray:
    """zeta = -Re s / |s| of the oscillatory poles of the linearisation at rest at ``q``,
    from the eigenvalues of its A (numpy, not the toolkit's modal summary)."""
    sys = fc.linearize(model, fc.equilibrium(model, q))
    s = np.linalg.eigvals(np.asarray(sys.A, dtype=float))
    pairs = s[s.imag > 1e-6 * np.max(np.abs(s))]
    return -pairs.real / np.abs(pairs)


def _model(*overrides: str):
    return fc.load_model(
        MODEL,
        payload=2.0,
        fidelity="amm:2",
        gravity=[0.0, 0.0],
        configuration=[30.0, 0.0, 0.0],
        overrides=list(overrides),
    )


def test_modal_damping_puts_the_asked_zeta_on_every_coupled_pole_at_the_design_pose():
    """At rest without gravity the linearisation is M q'' + D q' + K q = 0 at the pose itself,
    for which classical modal damping is exact: what is left is eigenvalue round-off (the
    poles are separated by > 10 %, so ~1e-12), hence the 1e-9 tolerance."""
    model = _model("damping_form=modal", "damping_zeta=0.02")
    zetas = _pole_zetas(model, POSE)
    assert zetas.size == 6  # 2 modes x 3 links, every one an oscillatory pair
    assert zetas == pytest.approx(0.02, abs=1e-9)
    # the per-clamped-mass-mode ratio of 0.02 gives the coupled poles other zetas
    per_link = _pole_zetas(_model(*(f"links[{i}].damping_ratio=0.02" for i in (1, 2, 3))), POSE)
    assert np.max(np.abs(per_link - 0.02)) > 0.05
    # away from the pose it was fitted at, the ratios move (the mass matrix changes)
    elsewhere = _pole_zetas(model, np.radians([30.0, 90.0, 0.0]))
    assert np.max(np.abs(elsewhere - 0.02)) > 1e-4


def test_the_damping_keys_are_checked_and_recorded():
    with pytest.raises(SpecError, match="damping_form = 'modal' needs damping_zeta"):
        fc.load_arm(MODEL, ["damping_form=modal"])
    with pytest.raises(SpecError, match="damping_zeta applies to damping_form = 'modal' only"):
        fc.load_arm(MODEL, ["damping_zeta=0.01"])
    arm = fc.load_arm(MODEL, ["damping_form=modal", "damping_zeta=0.01"])
    with pytest.raises(ModelFamilyUnavailable, match="'modal'.*assumed modes only"):
        fc.build_model(arm, "fem:2")
    assert arm.damping_summary() == {"form": "modal", "zeta_coupled_modes": 0.01}
    one = fc.load_model(
        ROOT / "tests" / "data" / "models" / "one_link.toml",
        fidelity="amm:1",
        overrides=["damping_form=modal", "damping_zeta=0.05"],
    )
    pd = fc.design(one, fc.equilibrium(one, np.radians([10.0])), fc.load_controller("pd"))
    move = fc.Move(start=np.radians([0.0]), target=np.radians([10.0]), time=0.2)
    run = fc.closed_loop(one, pd, move, duration=0.5, metrics=fc.MetricSettings(0.1))
    assert run.summary["plant"]["damping"] == {"form": "modal", "zeta_coupled_modes": 0.05}


def test_linearize_says_what_the_damping_is_beside_the_zeta_it_gives(capsys):
    from flexctrl import cli

    args = ["linearize", str(MODEL), "--q", "30", "0", "0", "--fidelity", "amm:1"]
    args += ["--set", "gravity=[0.0, 0.0]"]
    assert cli.main(args) == 0
    out = capsys.readouterr().out
    assert "damping_form = 'ratio', each link's damping_ratio" in out
    assert "acts per clamped-mass mode of that link (Eq 68's form)" in out
    assert cli.main([*args, "--set", "damping_form=modal", "--set", "damping_zeta=0.03"]) == 0
    out = capsys.readouterr().out
    assert "damping_zeta = 0.03 on every coupled elastic mode" in out
    assert out.count("  0.0300  ") == 3  # amm:1: three coupled elastic poles
