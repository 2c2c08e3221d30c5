"""A payload grasped at rest between two moves: plant swap, move sequence, re-identification."""

from __future__ import annotations

import numpy as np
import pytest

import flexctrl as fc
from flexctrl.errors import SpecError

START = np.radians([0.0, 0.0, 90.0])
OUT = np.radians([30.0, 0.0, 90.0])
MOVES = fc.MoveSequence((fc.Move(START, OUT, time=1.5), fc.Move(OUT, START, time=1.5, t_start=3.0)))


def rigid(payload: float):
    return fc.load_model("subedi3link", payload=payload, fidelity="rigid", gravity=[0.0, 0.0])


def test_a_sequence_is_its_moves_one_after_the_other():
    path = MOVES.joint_reference()
    t = np.linspace(0.0, 5.0, 501)
    first, second = (m.joint_reference() for m in MOVES.moves)
    expected = first.joints(t) + second.joints(t) - np.asarray(second.q_start)
    np.testing.assert_allclose(path.joints(t), expected, atol=1e-15)
    q, qd, qdd = path.derivatives(t)
    np.testing.assert_allclose(qd[1:-1], np.gradient(q, t, axis=0)[1:-1], atol=2e-3)
    assert path.t_arrive == 4.5 and path.q_target == tuple(START)


def test_moves_that_do_not_chain_are_refused():
    with pytest.raises(SpecError, match="before move 1 arrives"):
        fc.MoveSequence((fc.Move(START, OUT, time=1.5), fc.Move(OUT, START, time=1.5, t_start=1.0)))
    with pytest.raises(SpecError, match="not where move 1 ends"):
        fc.MoveSequence((fc.Move(START, OUT, time=1.5), fc.Move(START, OUT, time=1.5, t_start=2)))


def test_a_change_to_the_same_payload_changes_nothing():
    model = rigid(2.0)
    s = fc.load_controller("pd")
    runs = []
    for changes in ((), [(2.5, 2.0)]):
        ctrl = fc.design(model, fc.equilibrium(model, OUT), s)
        runs.append(fc.closed_loop(model, ctrl, MOVES, 7.0, payload_changes=changes))
    np.testing.assert_allclose(
        runs[1].trajectory.states, runs[0].trajectory.states, rtol=0, atol=1e-12
    )


def test_a_grasp_at_rest_is_felt_and_re_identified_on_the_next_move():
    model = rigid(2.0)
    s = fc.load_controller("lqr_payload")
    s = s.__class__(**{**s.__dict__, "sensors": s.sensors.__class__(outputs=("joints",))})
    ctrl = fc.design(model, fc.equilibrium(model, OUT), s)
    res = fc.closed_loop(model, ctrl, MOVES, 7.0, plant=rigid(0.0), payload_changes=[(2.5, 3.0)])
    trace = res.payload_estimate
    before = trace["mean"][np.searchsorted(trace["time"], 2.4)]
    assert abs(before - 0.0) < 0.2  # the first move identified the bare arm
    assert abs(trace["mean"][-1] - 3.0) < 0.2  # the move back identified the grasp
    assert 3.0 <= res.metrics["payload_estimate_time"] < 3.0 + 2.0
    assert res.model.spec.payload.mass == 3.0 and res.metrics["stable"] == 1
    with pytest.raises(SpecError, match="payload_changes.mass"):
        fc.closed_loop(model, ctrl, MOVES, 7.0, payload_changes=[(2.5, -1.0)])
