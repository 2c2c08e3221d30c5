"""Reference trajectories against finite differences and the model's own dynamics."""

from __future__ import annotations

import numpy as np
import pytest

from flexctrl.control.reference_trajectory import ReferenceTrajectory
from flexctrl.dynamics.build import build_model
from flexctrl.errors import SpecError
from flexctrl.linear import equilibrium
from flexctrl.scenes.run_closed_loop_scene import run_closed_loop_scene
from flexctrl.spec.arm import load_arm
from flexctrl.spec.reference import JointReference
from flexctrl.spec.scene import load_scene

SCENE = "studies/scenes/move_joint1_30deg.toml"
START, TARGET = (
    (0.1, -0.2, 0.3),
    tuple(np.radians([30.0, 20.0, -10.0]) + np.array([0.1, -0.2, 0.3])),
)


@pytest.fixture(scope="module")
def horizontal():
    arm = load_arm("models/subedi3link.toml", overrides=["gravity=[0.0, 0.0]"]).with_payload(2.0)
    return build_model(arm, "amm:2")


@pytest.fixture(scope="module")
def vertical():
    return build_model(load_arm("models/subedi3link.toml").with_payload(1.0), "amm:1")


def test_quintic_derivatives_match_finite_differences_and_the_end_conditions():
    path = JointReference(START, TARGET, "quintic", move_time=1.3, t_start=0.2)
    t = np.linspace(0.0, 2.0, 401)
    h = 1e-5
    for k in range(3):
        d_plus = path.derivatives(t + h, order=3)[k]
        d_minus = path.derivatives(t - h, order=3)[k]
        exact = path.derivatives(t, order=3)[k + 1]
        fd = (d_plus - d_minus) / (2 * h)
        smooth = np.abs(t - 0.2) > 2 * h
        smooth &= np.abs(t - 1.5) > 2 * h
        scale = np.max(np.abs(exact)) + 1e-300
        # central differences: error h^2/6 * next derivative, far below 1e-6 of the scale here
        np.testing.assert_allclose(fd[smooth], exact[smooth], atol=1e-6 * scale)
    q, qd, qdd = path.derivatives(np.array([0.0, 0.2, 1.5, 1.9]))
    np.testing.assert_allclose(q[[0, 1]], [START, START], atol=1e-15)
    np.testing.assert_allclose(q[[2, 3]], [TARGET, TARGET], atol=1e-15)
    assert np.all(qd == 0) and np.all(qdd == 0)  # at rest at both ends
    assert path.t_arrive == pytest.approx(1.5)
    # the minimum-jerk peaks: 1.875 dq/T at mid-move, 5.774 dq/T^2
    dense = np.linspace(0.2, 1.5, 20001)
    _, qd, qdd = path.derivatives(dense)
    delta = np.array(TARGET) - np.array(START)
    np.testing.assert_allclose(np.max(np.abs(qd), axis=0), 1.875 * np.abs(delta) / 1.3, rtol=1e-6)
    np.testing.assert_allclose(
        np.max(np.abs(qdd), axis=0), 10 / np.sqrt(3) * np.abs(delta) / 1.3**2, rtol=1e-4
    )


def test_step_profile_and_its_validation():
    step = JointReference(START, TARGET)
    np.testing.assert_allclose(step.joints([0.0, 5.0]), [TARGET, TARGET])
    assert step.t_arrive == 0.0
    with pytest.raises(SpecError, match="profile.*'step', 'quintic'"):
        JointReference(START, TARGET, "cubic")
    with pytest.raises(SpecError, match="move_time.*> 0 s"):
        JointReference(START, TARGET, "quintic", move_time=0.0)


@pytest.mark.parametrize("model_name", ["horizontal", "vertical"])
def test_reference_state_is_consistent_with_the_model(request, model_name):
    """At (x_ref, u_ref) the model accelerates the joints along the path, the links not at all."""
    model = request.getfixturevalue(model_name)
    path = JointReference(START, TARGET, "quintic", move_time=1.5)
    ref = ReferenceTrajectory(model, path)
    t = np.linspace(0.0, 1.8, 61)
    X, U, Us = ref.evaluate(t)
    acc = np.array(model.functions["f"].map(t.size)(X.T, U.T), dtype=float).T[:, model.n_q :]
    _q, _qd, qdd = path.derivatives(t)
    np.testing.assert_allclose(acc[:, : model.n_u], qdd, atol=1e-7 * np.max(np.abs(qdd)))
    assert np.max(np.abs(acc[:, model.n_u :])) < 1e-6 * np.max(np.abs(qdd))
    # u_static is the holding torque of the static equilibrium at q_ref (equilibrium()
    # independently)
    for i in (0, 30, 60):
        op = equilibrium(model, X[i, : model.n_u])
        np.testing.assert_allclose(Us[i], op.u, atol=1e-8 * max(1.0, np.max(np.abs(op.u))))
    # after the move: the target's equilibrium
    target = equilibrium(model, np.array(TARGET))
    np.testing.assert_allclose(X[-1], target.x, atol=1e-9)
    np.testing.assert_allclose(U[-1], target.u, atol=1e-7 * max(1.0, np.max(np.abs(target.u))))


def test_quasi_static_rates_match_finite_differences_of_the_deflection(horizontal):
    ref = ReferenceTrajectory(horizontal, JointReference(START, TARGET, "quintic", move_time=1.5))
    t = np.linspace(
        0.05, 1.45, 57
    )  # inside the move: q_f* has kinks where the jerk jumps (t = 0, 1.5 s)
    h = 1e-5
    n, N = horizontal.n_u, horizontal.n_q
    X = ref.evaluate(t)[0]
    fd = (ref.evaluate(t + h)[0] - ref.evaluate(t - h)[0]) / (2 * h)
    # qd_f* is the implicit-function derivative with the elastic accelerations neglected in the
    # rates' own time derivative (the quasi-static assumption): 1e-3 of its scale bounds that term
    # here
    np.testing.assert_allclose(fd[:, n:N], X[:, N + n :], atol=1e-3 * np.max(np.abs(X[:, N + n :])))
    np.testing.assert_allclose(fd[:, :n], X[:, N : N + n], atol=1e-7)


def test_a_step_reference_is_the_target_equilibrium(horizontal):
    ref = ReferenceTrajectory(horizontal, JointReference(START, TARGET))
    op = equilibrium(horizontal, np.array(TARGET))
    x, u, us = ref.at(0.0, 0.01)
    np.testing.assert_allclose(x, op.x, atol=1e-12)
    np.testing.assert_allclose(u, op.u, atol=1e-9)
    X, U, _ = ref.window(0.37, 0.01, 5)  # off-grid: evaluated directly
    np.testing.assert_allclose(X, np.tile(op.x, (5, 1)), atol=1e-12)


def test_scene_reference_keys_are_validated():
    with pytest.raises(SpecError, match="target.move_time"):
        load_scene(SCENE, ["target.move_time=-1.0"])
    with pytest.raises(
        SpecError, match="target.profile.*'step', 'quintic'.*did you mean 'quintic'"
    ):
        load_scene(SCENE, ['target.profile="quintc"'])
    step = load_scene(
        SCENE, ['target.profile="step"']
    )  # a study may switch profiles; the step ignores move_time
    assert step.t_arrive == 0.0 and step.move_time == 0.0
    with pytest.raises(SpecError, match="target.deflection.*'quasi_static', 'static'"):
        load_scene(SCENE, ['target.deflection="zero"'])
    with pytest.raises(SpecError, match="settle_allowance.*after the move"):
        load_scene(SCENE, ["metrics.settle_allowance=6.6"])


def _pd_residual(overrides):
    scene = load_scene(SCENE, overrides)
    result = run_closed_loop_scene(scene, None, controller="controllers/pd.toml", plots=False)
    return result.summary["metrics"]


def test_pd_leaves_less_residual_with_the_quintic_than_with_the_step():
    """Same PD, same window (from 4 s on), 2 kg: the smooth reference leaves less tip error."""
    quintic = _pd_residual(["metrics.settle_allowance=2.5", "duration=6.0"])
    step = _pd_residual(["metrics.settle_allowance=4.0", 'target.profile="step"', "duration=6.0"])
    assert quintic["tip_residual_rms"] < 0.5 * step["tip_residual_rms"]
    assert quintic["tip_residual_peak"] < step["tip_residual_peak"]
