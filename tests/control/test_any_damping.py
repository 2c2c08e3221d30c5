"""``controllers/lqr_any_damping.toml``: stable whatever the arm's structural damping in 0-1 %.

Judged by the loop layer's linear verdict on plants with another damping than the design model's,
and by a nonlinear run of the README's move on the arm as its file ships it (no damping), where
``controllers/lqr.toml`` diverges.
"""

import warnings

import numpy as np
import pytest
from support import scene_arm

import flexctrl as fc
from flexctrl.loop.verdict import linear_closed_loop_radius

TARGET = np.radians([30.0, 0.0, 0.0])


def arm(zeta: float):
    """The horizontal 2 kg arm, two modes per link, damping ratio ``zeta`` on every link."""
    return scene_arm(2.0, start_deg=None, zeta=zeta)


def designed(name: str, model):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", fc.DesignWarning)
        return fc.design(model, fc.equilibrium(model, TARGET), fc.load_controller(name))


@pytest.mark.parametrize("design_zeta", [0.0, 0.005])
def test_the_linear_verdict_holds_for_plant_damping_0_to_1_percent(design_zeta):
    ctrl = designed("controllers/lqr_any_damping.toml", arm(design_zeta))
    for plant_zeta in (0.0, 0.005, 0.01):
        assert linear_closed_loop_radius(arm(plant_zeta), ctrl, TARGET) < 1.0, plant_zeta


def test_the_undamped_arm_runs_where_lqr_toml_diverges():
    model = arm(0.0)
    move = fc.Move(start=np.radians([0, 0, 0]), target=TARGET, time=1.5)
    judge = fc.MetricSettings(settle_allowance=1.0)
    tuned = fc.closed_loop(
        model,
        designed("controllers/lqr.toml", model),
        move,
        duration=4.0,
        metrics=judge,
        on_divergence="record",
    )
    assert not tuned.metrics["stable"]
    ctrl = designed("controllers/lqr_any_damping.toml", model)
    result = fc.closed_loop(model, ctrl, move, duration=4.0, metrics=judge)
    assert result.metrics["stable"]
    assert result.metrics["tip_residual_rms"] < 1e-3  # m: settled after the move
    assert linear_closed_loop_radius(model, ctrl, TARGET) < 1.0
