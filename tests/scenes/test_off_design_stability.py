"""A controller designed at one configuration and payload, run elsewhere.

The verdict of the run (``stable``) is checked against an independent linear one: the
spectral radius of the plant's own linearisation at the target closed with the
controller's gain (``closed_loop_radius``).
"""

from __future__ import annotations

import math

import pytest

from flexctrl.errors import SimulationError
from flexctrl.scenes.run_closed_loop_scene import run_closed_loop_scene
from flexctrl.spec.scene import load_scene
from flexctrl.study import execute_run

SCENE = "studies/scenes/move_joint1_30deg.toml"
DESIGN = ["design_configuration=[30.0, 0.0, 0.0]", "design_payload=2.0", "duration=5.0"]


def _scene(payload: float, q2: float, q3: float):
    return load_scene(SCENE, DESIGN + [f"payload={payload}", f"initial.q=[0.0, {q2}, {q3}]"])


def test_far_from_the_design_point_with_a_heavy_payload_the_lqr_loop_is_unstable():
    result = run_closed_loop_scene(
        _scene(4.0, 135.0, 90.0),
        None,
        controller="tests/data/controllers/lqr_full_state.toml",
        plots=False,
        on_divergence="record",
    )
    m = result.summary["metrics"]
    assert m["stable"] == 0
    assert m["closed_loop_radius"] > 1.0  # linearly unstable too
    assert m["final_tip_error"] > 10 * result.scene.band
    assert result.summary["design"]["configuration_deg"] == pytest.approx([30.0, 0.0, 0.0])


def test_near_the_design_point_the_same_lqr_is_stable():
    result = run_closed_loop_scene(
        _scene(2.0, 0.0, -90.0),
        None,
        controller="tests/data/controllers/lqr_full_state.toml",
        plots=False,
        on_divergence="record",
    )
    m = result.summary["metrics"]
    assert m["stable"] == 1 and m["closed_loop_radius"] < 1.0
    assert math.isnan(m["divergence_time"])  # it did not diverge
    assert result.summary["metric_notes"] == {"divergence_time": "the run did not diverge"}
    assert m["final_tip_error"] < result.scene.stable_band


def test_a_diverging_run_is_recorded_as_a_finite_ok_row_or_raised_by_simulate(tmp_path):
    """Leaving the bounds stops the run: recorded (stable = 0, divergence_time) or raised."""
    # a tight deflection bound makes the unstable loop leave it within the run
    overrides = DESIGN + [
        "payload=0.0",
        "initial.q=[0.0, 90.0, 0.0]",
        "metrics.divergence_deflection=0.01",
    ]
    scene = load_scene(SCENE, overrides)
    with pytest.raises(SimulationError, match="diverged at t = .*link . tip deflection"):
        run_closed_loop_scene(
            scene, None, controller="tests/data/controllers/lqr_full_state.toml", plots=False
        )
    settings = {
        "executor": "closed_loop",
        "scene": str(SCENE),
        "model": "models/subedi3link.toml",
        "controller": "tests/data/controllers/lqr_full_state.toml",
        "payload": 0.0,
        "q0_deg": [0.0, 90.0, 0.0],
        "fidelity": None,
        "overrides": [f"scene.{o}" for o in DESIGN] + ["scene.metrics.divergence_deflection=0.01"],
        "digests": {},
        "seed": 1,
    }
    row = execute_run(
        "closed_loop", settings, {"metrics": ["stable", "divergence_time", "tip_residual_rms"]}
    )
    assert row["status"] == "ok", row["error"]
    assert row["metrics"]["stable"] == 0
    assert 0 < row["metrics"]["divergence_time"] < 5.0
    # the residual window (from 2.5 s) never opened: no residual, the reason in the row
    assert math.isnan(row["metrics"]["tip_residual_rms"])
    assert (
        "no tip_residual_rms, tip_residual_peak, settling_time: the run diverged at"
        in (row["error"])
    )
    assert "before its residual window opened at 2.5 s" in row["error"]
    assert row["trajectories"]["t"][-1] == pytest.approx(
        row["metrics"]["divergence_time"], abs=0.011
    )
