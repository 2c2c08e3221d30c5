"""The payload-change scene: its keys, their refusals, and a short run on the rigid arm."""

from __future__ import annotations

import math

import pytest

import flexctrl as fc
from flexctrl.errors import SpecError
from flexctrl.loop.result import tip_at_rest
from flexctrl.spec.reference import JointSequence

SCENE = "studies/scenes/payload_change.toml"


def test_the_shipped_scene_moves_out_and_back_and_grasps_at_rest():
    scene = fc.load_scene(SCENE)
    assert scene.payload_changes == ((3.0, 4.0),)
    path = scene.joint_reference()
    assert isinstance(path, JointSequence) and scene.t_arrive == 5.5
    assert scene.final_q == scene.start_q and scene.target_q != scene.start_q
    assert scene.settings()["payload_changes"] == [{"time_s": 3.0, "mass_kg": 4.0}]


@pytest.mark.parametrize(
    "sets, key, words",
    [
        (["return.t_start=1.0"], "return.t_start", "at or after the arrival"),
        (["payload_changes[1].mass=-1.0"], "payload_changes[1].mass", ">= 0"),
        (["payload_changes[1].time=99.0"], "payload_changes[1].time", "within the run"),
        (["return.when=4.0"], "return.when", "unknown key"),
    ],
)
def test_bad_values_are_refused_by_key(sets, key, words):
    with pytest.raises(SpecError) as info:
        fc.load_scene(SCENE, sets)
    assert f"'{key}'" in str(info.value) and words in str(info.value)


def test_on_the_rigid_arm_a_fixed_pd_comes_back_and_is_judged_at_the_start():
    sets = ["fidelity=rigid", "noise.enabled=false", "duration=7.0"]
    res = fc.run_scene(fc.load_scene(SCENE, sets), controller="pd")
    assert res.model.spec.payload.mass == 4.0  # judged on the plant it ends on
    assert "payload_estimate_error" not in res.metrics
    q1 = res.trajectory.states[:, 0]
    assert abs(q1[-1] - res.scene.start_q[0]) < math.radians(2.0)  # it came back
    tip_start = tip_at_rest(res.model, res.scene.start_q)
    assert math.dist(res.trajectory.tip[-1], tip_start) == pytest.approx(
        res.metrics["final_tip_error"], abs=res.metrics["final_tip_error"]
    )
