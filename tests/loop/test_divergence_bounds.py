"""The divergence bounds on link deflection: 0.1 of the length on a stiff arm, room for the
bending a light arm's torques cause on an ordinary move."""

from __future__ import annotations

import numpy as np
import pytest
from support import MODEL, ROOT

import flexctrl as fc
from flexctrl.loop.monitors import deflection_bounds
from flexctrl.spec.arm import load_arm

ONE_LINK = ROOT / "tests" / "data" / "models" / "one_link.toml"


def test_a_stiff_arm_keeps_a_tenth_of_its_length_and_a_light_one_gets_its_torques_room():
    stiff = load_arm(MODEL)
    lengths = np.array([link.length for link in stiff.links])
    # tau L^2 / (2 EI) by hand: 200 * 2.25 / 36090, 100 * 2.25 / 14072.2, 50 * 2.25 / 4822.8 (m)
    static = np.array([200 * 2.25 / 36090, 100 * 2.25 / 14072.2, 50 * 2.25 / 4822.8])
    assert np.all(4 * static < 0.1 * lengths)
    assert deflection_bounds(stiff) == pytest.approx(0.1 * lengths)
    assert deflection_bounds(stiff, 0.01) == pytest.approx(0.01 * lengths)
    light = load_arm(ONE_LINK, ["links[1].EI=100.0"])  # 20 N m torque: 0.1 m static at the tip
    assert deflection_bounds(light) == pytest.approx([0.4])
    lighter = load_arm(ONE_LINK, ["links[1].EI=20.0"])  # 0.5 m: capped at half the length
    assert deflection_bounds(lighter) == pytest.approx([0.5])


def test_a_light_arms_one_second_move_runs_where_a_tenth_of_its_length_stopped_it():
    """One 1 m link with EI = 20 N m^2 (first mode near 1.6 Hz) turned 60 deg in 1 s by PD."""
    model = fc.load_model(ONE_LINK, fidelity="amm:1", overrides=["links[1].EI=20.0"])
    pd = fc.design(model, fc.equilibrium(model, np.radians([60.0])), fc.load_controller("pd"))
    move = fc.Move(start=np.radians([0.0]), target=np.radians([60.0]), time=1.0)
    old = fc.closed_loop(
        model,
        pd,
        move,
        duration=4.0,
        metrics=fc.MetricSettings(divergence_deflection=0.1),
        on_divergence="record",
    )
    assert old.metrics["stable"] == 0 and old.metrics["divergence_time"] < 1.0
    assert "divergence_deflection = 0.1 of its 1 m length" in old.summary["divergence"]["message"]
    # its figure says the window never opened, and shades nothing
    tip = old.plot().axes[0]
    assert tip.get_title().startswith("no residual-vibration window: the run ended at 0.32")
    assert not tip.patches and "no residual" in tip.get_legend().get_texts()[0].get_text()
    run = fc.closed_loop(model, pd, move, duration=4.0)  # the default bounds: raises if crossed
    assert run.metrics["stable"] == 1 and run.metrics["settled_within_band"] == 1
    # it bends past the old bound on the way (measured on the trajectory, not by the monitor)
    assert np.max(np.abs(run.trajectory.deflections)) > 0.1
    assert run.metrics["tip_residual_rms"] < 5e-3
