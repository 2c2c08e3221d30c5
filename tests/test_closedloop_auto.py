"""Closed-loop scenes with ``fidelity = "auto"``: the plant model chosen from a tip tolerance (issue 7).

The choice is checked against runs the chooser did not make: the reference plant and
the chosen plant are run directly here (full plant rate, through
:func:`flexctrl.scenes.closed_loop.run_closed_loop_scene` with a concrete fidelity) and their
tip paths compared with :func:`flexctrl.sim.tip_error.tip_error`.  No choice or
error is hard-coded: the tolerance is the only number the assertions use.

The scene is the quickstart's move (1.5 s quintic, 2 kg, q2, q3 = 90, -90 deg) cut to
2.8 s, with the ladder cut at ``amm:2`` (reference ``amm:3``) and the LQR (10 ms
sample), so the choice needs a few small compiled models.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from flexctrl.scenes import auto as auto_fidelity
from flexctrl.scenes.cache import SceneCache
from flexctrl.sim.tip_error import tip_error
from flexctrl.cli import main
from flexctrl.scenes.loop_setup import AUTO_DESIGN_FIDELITY
from flexctrl.scenes.closed_loop import check_auto, run_closed_loop_scene
from flexctrl.loop.mismatch import state_projection
from flexctrl.errors import SpecError
from flexctrl.spec.scene import load_scene

SCENE = "studies/scenes/move_joint1_30deg.toml"
CONTROLLER = "controllers/lqr.toml"
SHORT = ["duration=2.8", "initial.q=[0.0, 90.0, -90.0]"]
TOL = 3e-3  # m
OPTIONS = {"top": 2, "reference": "amm:3"}
#: One cache for the module: the runs below share models and the choice, as a study worker does.
CACHE = SceneCache()


def _scene(*extra: str):
    return load_scene(SCENE, [*SHORT, "fidelity='auto'", f"tolerance={TOL!r}", *extra])


@pytest.fixture(scope="module")
def auto_run():
    return run_closed_loop_scene(_scene(), controller=CONTROLLER, auto_options=OPTIONS, cache=CACHE)


@pytest.mark.slow  # the module fixture: ~20 s with compiled models on disk, ~30 s without
def test_auto_resolves_records_and_meets_the_tolerance_against_a_direct_reference_run(auto_run):
    summary = auto_run.summary
    choice = summary["fidelity_choice"]
    ladder = choice["ladder"]
    assert choice["choice"] in ladder and choice["kind"] == "closed_loop"
    assert summary["plant"]["fidelity"] == choice["choice"]
    assert summary["design"]["fidelity"] == AUTO_DESIGN_FIDELITY  # pinned, not the chosen plant
    metrics = summary["metrics"]
    assert metrics["chosen_modes"] == (0 if choice["choice"] == "rigid" else int(choice["choice"].split(":")[1]))
    assert metrics["chosen_dt"] == choice["dt_s"] == pytest.approx(auto_run.trajectory.meta["dt"])
    assert metrics["estimated_error"] == choice["estimated_error"] <= TOL
    # evidence: every rung simulated, the reference and its convergence checks
    rows = {c["fidelity"]: c for c in choice["candidates"]}
    assert choice["choice"] in rows and rows[choice["choice"]]["estimated_error_m"] == pytest.approx(choice["estimated_error"])
    conv = choice["reference"]["convergence"]
    assert max(conv["step_halving_m"], conv["rung_below_m"]) <= 0.5 * TOL

    # independent: run the reference plant directly at its step, compare the tip paths at the full plant rate
    ref = choice["reference"]
    direct_ref = run_closed_loop_scene(
        load_scene(SCENE, [*SHORT, f"fidelity='{ref['fidelity']}'", f"dt={ref['dt_s']!r}",
                           f"controller_fidelity='{AUTO_DESIGN_FIDELITY}'"]), controller=CONTROLLER).trajectory
    traj = auto_run.trajectory
    err = tip_error(direct_ref.time, direct_ref.tip, traj.time, traj.tip)
    assert err.max <= TOL
    # the chooser compared on the scene's grid, a subset of these samples: never more than here
    assert choice["reference_error"] <= err.max * (1 + 1e-9) + 1e-12
    # and the chosen run is what a direct run of the chosen plant gives
    direct = run_closed_loop_scene(
        load_scene(SCENE, [*SHORT, f"fidelity='{choice['choice']}'", f"dt={choice['dt_s']!r}",
                           f"controller_fidelity='{AUTO_DESIGN_FIDELITY}'"]), controller=CONTROLLER).trajectory
    np.testing.assert_allclose(direct.tip, traj.tip, rtol=0, atol=1e-12)


@pytest.mark.slow  # the module fixture: ~20 s with compiled models on disk, ~30 s without
def test_choice_is_kept_in_the_cache_and_keyed_by_the_controller(auto_run):
    before = CACHE.stats()["closed_choices"]
    again = run_closed_loop_scene(_scene(), controller=CONTROLLER, auto_options=OPTIONS, cache=CACHE)
    after = CACHE.stats()["closed_choices"]
    assert after["hits"] == before["hits"] + 1 and after["misses"] == before["misses"]
    assert again.summary["fidelity_choice"]["choice"] == auto_run.summary["fidelity_choice"]["choice"]
    scene = _scene()
    base = auto_fidelity.closed_loop_key(scene, CONTROLLER, ())
    assert auto_fidelity.closed_loop_key(scene, CONTROLLER, ("weights.joint=1.0",)) != base
    assert auto_fidelity.closed_loop_key(scene, "controllers/pd.toml", ()) != base
    assert auto_fidelity.closed_loop_key(_scene("payload=0.0"), CONTROLLER, ()) != base
    assert auto_fidelity.closed_loop_key(_scene("initial.q=[0.0, 0.0, 0.0]"), CONTROLLER, ()) != base
    assert auto_fidelity.closed_loop_key(_scene("tolerance=1e-3"), CONTROLLER, ()) == base  # the tolerance keys the choice cache


@pytest.mark.parametrize("sets, key", [
    (["fidelity='auto'", "tolerance=-1e-3"], "tolerance"),
    (["fidelity='auto'", "tolerance=0.0"], "tolerance"),
    (["fidelity='auto'"], "tolerance"),  # missing
])
def test_bad_tolerance_with_auto_is_refused_naming_the_key(sets, key):
    with pytest.raises(SpecError) as info:
        load_scene(SCENE, [*SHORT, *sets])
    assert f"'{key}'" in str(info.value) and "move_joint1_30deg.toml" in str(info.value)


def test_auto_refusals_name_key_value_and_allowed():
    scene = _scene()
    with pytest.raises(SpecError, match=r"'tolerance'.*-0\.5.*allowed"):
        auto_fidelity.choose_closed_loop_fidelity(scene, -0.5, controller=CONTROLLER)
    with pytest.raises(SpecError, match=r"'integrator'.*'cvodes'.*allowed: 'rk4'"):
        check_auto(_scene("integrator='cvodes'"), CONTROLLER)
    with pytest.raises(SpecError, match=r"'controller_fidelity'.*allowed"):
        auto_fidelity.choose_closed_loop_fidelity(scene, TOL, controller=CONTROLLER)  # design model not pinned


@pytest.mark.slow  # the module fixture: ~20 s with compiled models on disk, ~30 s without
def test_fidelity_cli_json_for_a_closed_loop_scene(capsys, auto_run):
    sets = [item for s in [*SHORT, f"tolerance={TOL!r}"] for item in ("--set", s)]
    code = main(["fidelity", SCENE, "--controller", CONTROLLER, "--top", "2", "--reference", "amm:3", "--json",
                 "--set", f"controller_fidelity='{AUTO_DESIGN_FIDELITY}'", *sets])
    assert code == 0
    data = json.loads(capsys.readouterr().out)
    assert list(data)[:1] == ["choice"]
    for key in ("choice", "estimated_error", "reference_error", "cost_ratio"):
        assert key in data
    assert data["choice"] == auto_run.summary["fidelity_choice"]["choice"]
    assert data["estimated_error"] <= TOL and math.isfinite(data["cost_ratio"])
    # a bad --tol is refused naming the option
    assert main(["fidelity", SCENE, "--tol", "-1", *sets]) == 2
    assert "--tol" in capsys.readouterr().err


def test_state_projection_matches_modes_by_name_and_the_modes_agree_across_rungs():
    from flexctrl.linear import state_names
    from flexctrl.scenes.arm import scene_arm

    plant_scene = _scene().plant
    arm = scene_arm(plant_scene)
    two = CACHE.model(arm, "amm:2", plant_scene.modes, plant_scene.q0)
    three = CACHE.model(arm, "amm:3", plant_scene.modes, plant_scene.q0)
    one = CACHE.model(arm, "amm:1", plant_scene.modes, plant_scene.q0)
    # the claim the projection rests on: a link's first modes are the same at every rung
    for low, high in zip(two.info["link_frequencies_rad_s"], three.info["link_frequencies_rad_s"]):
        np.testing.assert_allclose(low, high[: len(low)], rtol=1e-9)
    x = np.arange(1.0, three.n_x + 1.0)
    P = state_projection(three, state_names(two))
    names3 = state_names(three)
    assert [names3[int(np.argmax(row))] for row in P] == list(state_names(two))
    np.testing.assert_array_equal(P @ x, [x[names3.index(n)] for n in state_names(two)])
    # a plant with fewer modes reads zero for the design's missing ones
    P1 = state_projection(one, state_names(two))
    assert P1.shape == (two.n_x, one.n_x) and not np.any(P1[list(state_names(two)).index("qf12")])
