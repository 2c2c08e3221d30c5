"""fidelity = "auto": the cheapest model that meets a tip tolerance (issue 7).

The choices are checked against a reference that the chooser did not use to make
them (the reference only judges), the reported reference error is recomputed
here from independent runs through :func:`flexctrl.scenes.arm_scene.run_arm_scene`, and no
expected choice or error is hard-coded: the tests compare a slow light move with
a fast heavy one and every error with the tolerance given.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from flexctrl.fidelity.ladder import FidelityChoice, excitation_bandwidth
from flexctrl.sim.rk4 import RK4_STABILITY_LIMIT as RK4_LIMIT
from flexctrl.sim.rk4 import RK4_MARGIN, rk4_step
from flexctrl.scenes.auto import choose_fidelity
from flexctrl.scenes.cache import SceneCache
from flexctrl.sim.tip_error import tip_error
from flexctrl.cli import main
from flexctrl.errors import SpecError
from flexctrl.spec.fidelity import parse_fidelity
from flexctrl.scenes.arm_scene import run_arm_scene
from flexctrl.scenes import run_scene
from flexctrl.spec.scene import load_scene

SLOW = "studies/scenes/slow_move_light.toml"
SLOW_SET = ["duration=1.0"]
SLOW_OPTIONS = {"top": 2, "reference": "amm:3"}
#: One cache for the module, as a study worker keeps one.
CACHE = SceneCache()
HEAVY = "studies/scenes/bangbang_damped.toml"
HEAVY_SET = ["duration=0.6", "payload=4.0", "fidelity='auto'", "tolerance=2e-4"]


@pytest.fixture(scope="module")
def slow():
    scene = load_scene(SLOW, SLOW_SET)
    return scene, choose_fidelity(scene, scene.tolerance, **SLOW_OPTIONS, cache=CACHE)


def _check_choice(scene, choice: FidelityChoice, tol: float) -> None:
    assert choice.estimated_error <= tol
    assert choice.reference_error <= tol
    conv = choice.evidence["reference"]["convergence"]
    # the reference must be converged well inside the tolerance to judge the choice
    assert max(conv["step_halving_m"], conv["rung_below_m"]) <= 0.5 * tol
    # recompute the reference error from independent runs of the scene
    ref = choice.evidence["reference"]
    ref_scene = load_scene(scene.source, [*_sets(scene), f"fidelity='{ref['fidelity']}'", f"dt={ref['dt_s']!r}"])
    ref_run = run_arm_scene(ref_scene).trajectory
    own = load_scene(scene.source, [*_sets(scene), f"fidelity='{choice.choice}'", f"dt={choice.dt!r}"])
    run = run_arm_scene(own).trajectory
    err = tip_error(ref_run.time, ref_run.tip, run.time, run.tip)
    assert err.max == pytest.approx(choice.reference_error, rel=1e-6, abs=1e-12)
    # the error estimate of the choice is safety times its largest distance to the rungs above
    row = next(c for c in choice.evidence["candidates"] if c["fidelity"] == str(choice.choice))
    assert row["estimated_error_m"] == pytest.approx(choice.estimated_error)


def _sets(scene) -> list[str]:
    return SLOW_SET if scene.name == "slow_move_light" else HEAVY_SET


def test_slow_light_move_picks_a_low_fidelity(slow):
    scene, choice = slow
    assert choice.choice.modes_per_link is not None and choice.choice.modes_per_link <= 1
    _check_choice(scene, choice, scene.tolerance)
    assert 0 < choice.cost_ratio < 1
    # RK4 at the chosen step is stable with the documented margin, on the scene's grid
    model_omega = next(c for c in choice.evidence["candidates"] if c["fidelity"] == str(choice.choice))["omega_max_rad_s"]
    assert model_omega * choice.dt <= RK4_MARGIN * RK4_LIMIT + 1e-12
    assert scene.dt / choice.dt == pytest.approx(round(scene.dt / choice.dt))


@pytest.mark.slow
def test_fast_heavy_bangbang_needs_more_modes(slow):
    _slow_scene, slow_choice = slow
    scene = load_scene(HEAVY, HEAVY_SET)
    choice = choose_fidelity(scene, scene.tolerance, top=3, cache=CACHE)
    assert choice.choice.modes_per_link > slow_choice.choice.modes_per_link
    _check_choice(scene, choice, scene.tolerance)
    # the chosen rung's estimate meets the tolerance and the one below it does not (lowest rung)
    rows = {c["fidelity"]: c for c in choice.evidence["candidates"]}
    below = "rigid" if choice.choice.modes_per_link == 1 else f"amm:{choice.choice.modes_per_link - 1}"
    assert rows[below]["estimated_error_m"] > scene.tolerance


def test_choices_are_kept_in_the_callers_cache(slow):
    scene, choice = slow
    again = choose_fidelity(load_scene(SLOW, SLOW_SET), scene.tolerance, **SLOW_OPTIONS, cache=CACHE)
    assert again is choice
    assert choose_fidelity(load_scene(SLOW, SLOW_SET), 2 * scene.tolerance, **SLOW_OPTIONS, cache=CACHE) is not choice


def test_cli_json_has_the_four_keys(slow, capsys):
    _scene, choice = slow
    argv = ["fidelity", SLOW, "--tol", repr(choice.tolerance), "--set", "duration=1.0", "--top", "2",
            "--reference", "amm:3", "--json"]
    assert main(argv) == 0
    data = json.loads(capsys.readouterr().out)
    assert isinstance(data["choice"], str) and parse_fidelity(data["choice"]) == choice.choice
    for key in ("estimated_error", "reference_error", "cost_ratio"):
        assert isinstance(data[key], float) and math.isfinite(data[key]) and data[key] >= 0
    assert data["reference"]["fidelity"] == "amm:3"
    assert data["candidates"] and all(c["wall_time_s"] > 0 and "reference_error_max_m" in c for c in data["candidates"])
    # the table form prints the choice too
    assert main(argv[:-1]) == 0
    assert f"choice {choice.choice}" in capsys.readouterr().out


@pytest.mark.parametrize("argv, key", [
    (["--tol", "0"], "--tol"),
    (["--tol=-1e-3"], "--tol"),
    (["--tol", "nan"], "--tol"),
    (["--set", "tolerance=-1"], "tolerance"),
    (["--set", "fidelity='auto'", "--set", "tolerance=0.0", "--tol", "1e-3"], "tolerance"),
])
def test_bad_tolerance_exits_2_naming_the_key(argv, key, capsys):
    assert main(["fidelity", SLOW, *argv]) == 2
    err = capsys.readouterr().err
    assert f"key '{key}'" in err and SLOW in err


def test_auto_without_tolerance_is_refused():
    with pytest.raises(SpecError, match="key 'tolerance'.*fidelity = 'auto'"):
        load_scene("studies/scenes/bangbang.toml", ["fidelity='auto'"])


def test_unreachable_tolerance_exits_3_naming_the_best(slow, capsys):
    _scene, choice = slow
    tiny = 0.1 * min(c["estimated_error_m"] for c in choice.evidence["candidates"] if "estimated_error_m" in c)
    # the reference's own convergence is then not fine enough either, which is warned about
    with pytest.warns(UserWarning, match="may not be converged"):
        status = main(["fidelity", SLOW, "--tol", repr(tiny), "--set", "duration=1.0", "--top", "2", "--reference", "amm:3"])
    assert status == 3
    assert "best estimate" in capsys.readouterr().err


def test_auto_scene_runs_the_choice_and_records_it(slow, tmp_path):
    scene, choice = slow
    result = run_scene(scene, tmp_path, plots=False, auto_options=SLOW_OPTIONS, cache=CACHE)
    record = result.summary["fidelity_choice"]
    assert record["choice"] == str(choice.choice)  # the cached choice
    assert result.trajectory.meta["fidelity"] == record["choice"]
    assert result.trajectory.meta["dt"] == pytest.approx(record["dt_s"])
    assert record["reference_error"] <= scene.tolerance
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert saved["fidelity_choice"]["choice"] == record["choice"]
    assert saved["scene"]["fidelity"] == "auto"


def test_bandwidth_scales_inversely_with_pulse_length():
    base = load_scene(SLOW, SLOW_SET + ["input.t_accel=0.2", "input.t_decel=0.2"])
    longer = load_scene(SLOW, SLOW_SET + ["input.t_accel=0.4", "input.t_decel=0.4"])
    b1, b2 = (excitation_bandwidth(s, 3) for s in (base, longer))
    resolution = 1 / (4 * base.duration)  # zero-padded FFT bin (Hz)
    assert b1 / 2 == pytest.approx(b2, abs=2 * resolution)
    assert excitation_bandwidth(load_scene("studies/scenes/free_vibration.toml"), 3) is None


@pytest.mark.parametrize("omega", [0.0, 100.0, 2063.0, 12927.0])
def test_rk4_step_is_a_whole_fraction_of_the_scene_step_and_stable(omega):
    dt = rk4_step(omega, 1e-3)
    k = 1e-3 / dt
    assert k == pytest.approx(round(k))
    assert omega * dt <= RK4_MARGIN * RK4_LIMIT + 1e-12
    if round(k) > 1:  # the next larger whole fraction would not be stable
        assert omega * 1e-3 / (round(k) - 1) > RK4_MARGIN * RK4_LIMIT


def test_choose_rejects_bad_options(slow):
    scene, _ = slow
    with pytest.raises(SpecError, match="key 'reference'"):
        choose_fidelity(scene, 1e-3, top=2, reference="amm:2")
    with pytest.raises(SpecError, match="key 'top'"):
        choose_fidelity(scene, 1e-3, top=0)
    with pytest.raises(SpecError, match="key 'tolerance'"):
        choose_fidelity(scene, float("inf"))
    assert np.isfinite(scene.tolerance)
