"""fidelity = "auto" for arm scenes: the cheapest model that meets a tip tolerance.

The choices are checked against a reference that the chooser did not use to make
them (the reference only judges).  What the chooser reports is recomputed here by
other means:

* the error estimates, from the runs the chooser made (kept in :data:`CACHE`), with
  the tip distance written out here (the coarser path interpolated linearly onto
  the finer one's samples by index arithmetic, not through
  :func:`flexctrl.sim.tip_error.tip_error`) and the rule of the method (``safety``
  times the largest distance to the next two rungs, up to the reference model);
* the reference error, against the reference model integrated by another method
  (SUNDIALS CVODES, adaptive BDF, through :func:`flexctrl.sim.simulate`) and the
  chosen model re-run through ``simulate`` (uncompiled RK4), within the reference's
  own measured convergence;
* the integration step of every rung, from the models' ``omega_max`` and RK4's
  stability limit.

No expected choice or error is hard-coded: the tests compare a slow light move with
a fast heavy one and every error with the tolerance given.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from flexctrl.cli import main
from flexctrl.errors import SpecError
from flexctrl.fidelity.ladder import FidelityChoice, excitation_bandwidth
from flexctrl.scenes import run_scene
from flexctrl.scenes.auto import choose_fidelity, model_for, simulate_rung
from flexctrl.scenes.cache import SceneCache
from flexctrl.sim import simulate
from flexctrl.sim.rk4 import RK4_MARGIN, rk4_step
from flexctrl.sim.rk4 import RK4_STABILITY_LIMIT as RK4_LIMIT
from flexctrl.sim.tip_error import tip_error
from flexctrl.spec.fidelity import parse_fidelity
from flexctrl.spec.scene import load_scene

SLOW = "studies/scenes/slow_move_light.toml"
SLOW_SET = ["duration=1.0"]
SLOW_OPTIONS = {"top": 2, "reference": "amm:3"}
#: One cache for the module, as a study worker keeps one.
CACHE = SceneCache()
HEAVY = "studies/scenes/bangbang_damped.toml"
HEAVY_SET = ["duration=0.6", "payload=4.0", "fidelity='auto'", "tolerance=2e-4"]
#: The documented default safety factor (module docstring of flexctrl.fidelity.ladder, method step
#: 2).
SAFETY = 2.0
#: Largest error (m) allowed to the CVODES reference at its default tolerances (rtol 1e-8, atol
#: 1e-10): against runs at rtol 1e-12 it moved the tip by at most 2e-10 m on both scenes here.
CVODES_ERROR = 1e-9
#: What the slow choice left in CACHE's run store, taken before any test here runs a rung itself.
SLOW_CHOICE_RUNS: dict[str, int] = {}


@pytest.fixture(scope="module")
def slow():
    scene = load_scene(SLOW, SLOW_SET)
    choice = choose_fidelity(scene, scene.tolerance, **SLOW_OPTIONS, cache=CACHE)
    SLOW_CHOICE_RUNS.update(CACHE.stats().get("runs", {"entries": 0}))
    return scene, choice


def _distance(a, b) -> float:
    """Largest tip distance between two runs, the coarser interpolated onto the finer's samples.

    Written out by index arithmetic on the runs' uniform grids (the ladder's definition,
    :func:`flexctrl.fidelity.ladder.tip_distance`, without its code).
    """
    fine, coarse = (a, b) if a.dt <= b.dt else (b, a)
    for run in (fine, coarse):  # uniform grids from 0 (what the index arithmetic assumes)
        np.testing.assert_allclose(run.time, run.dt * np.arange(run.time.size), rtol=0, atol=1e-12)
    assert fine.time[-1] == pytest.approx(coarse.time[-1], abs=1e-12)
    position = fine.time / coarse.dt
    i = np.minimum(np.floor(position).astype(int), coarse.time.size - 2)
    w = (position - i)[:, None]
    moved = (1.0 - w) * coarse.tip[i] + w * coarse.tip[i + 1]
    return float(np.linalg.norm(moved - fine.tip, axis=1).max())


def _rung(m: int) -> str:
    return "rigid" if m == 0 else f"amm:{m}"


def _estimator(scene, choice: FidelityChoice):
    """``estimate(m) -> (distances, estimate)`` of rung ``m`` from the chooser's runs (step 2)."""
    ref_n = parse_fidelity(choice.evidence["reference"]["fidelity"]).count
    runs = {}

    def run(m: int):
        if m not in runs:
            runs[m] = simulate_rung(
                scene, _rung(m), cache=CACHE
            )  # the rung at its own step: the chooser's run
        return runs[m]

    def estimate(m: int) -> tuple[list[float], float]:
        distances = [_distance(run(m), run(k)) for k in range(m + 1, min(m + 2, ref_n) + 1)]
        return distances, SAFETY * max(distances)

    return estimate


def _reference_by_cvodes(scene, choice: FidelityChoice):
    """The reference model by CVODES on the reference's samples; the chosen model re-run.

    The chosen model is re-run by ``simulate``.
    """
    # both scenes start at rest, undeformed, at q = 0: the initial state is zero
    assert all(a == 0.0 for a in scene.q0) and not scene.qf0 and not any(scene.qd0 or ())
    ref = choice.evidence["reference"]
    runs = []
    for fidelity, method, dt in (
        (ref["fidelity"], "cvodes", ref["dt_s"]),
        (str(choice.choice), "rk4", choice.dt),
    ):
        model = model_for(scene, fidelity, CACHE)
        n = int(round(scene.duration / dt))
        assert n * dt == pytest.approx(scene.duration)
        u = scene.input.samples(n, dt, model.n_joints)
        options = {"compile": False} if method == "rk4" else {}
        runs.append(
            simulate(
                model, np.zeros(model.n_x), scene.duration, dt=dt, method=method, u=u, **options
            )
        )
    return runs


def _check_choice(scene, choice: FidelityChoice, tol: float) -> None:
    # the error estimates, recomputed from the runs with the method's rule
    estimate = _estimator(scene, choice)
    assert choice.evidence["safety"] == SAFETY
    rows = {row["fidelity"]: row for row in choice.evidence["candidates"]}
    for name, row in rows.items():
        if "estimated_error_m" in row:
            distances, mine = estimate(parse_fidelity(name).modes_per_link)
            assert row["distance_to_next_m"] == pytest.approx(distances[0], rel=1e-9, abs=1e-15)
            if len(distances) > 1:
                assert row.get("distance_to_second_next_m") == pytest.approx(
                    distances[1], rel=1e-9, abs=1e-15
                )
            assert row["estimated_error_m"] == pytest.approx(mine, rel=1e-9, abs=1e-15)
    m = choice.choice.modes_per_link
    assert choice.dt == rows[str(choice.choice)]["dt_s"]
    assert choice.estimated_error == pytest.approx(estimate(m)[1], rel=1e-9, abs=1e-15)
    assert estimate(m)[1] <= tol
    # the lowest rung that meets it: the rung below (when on the ladder) does not
    if _rung(m - 1) in choice.evidence["ladder"]:
        assert estimate(m - 1)[1] > tol

    # the reference error, against the reference model integrated by CVODES instead of RK4
    ref = choice.evidence["reference"]
    conv = ref["convergence"]
    cvodes, chosen = _reference_by_cvodes(scene, choice)
    rk4_reference = simulate_rung(
        scene, ref["fidelity"], "rk4", ref["dt_s"], cache=CACHE
    )  # the chooser's reference
    np.testing.assert_array_equal(cvodes.time, rk4_reference.time)
    # RK4 is 4th order: its error at step h is at most 16/15 of its distance from the run at h / 2
    slack = 16 / 15 * conv["step_halving_m"] + CVODES_ERROR
    reference_move = float(np.linalg.norm(cvodes.tip - rk4_reference.tip, axis=1).max())
    assert reference_move <= slack
    # the reference must be converged well inside the tolerance to judge the choice
    assert max(reference_move, conv["step_halving_m"], conv["rung_below_m"]) <= 0.5 * tol
    err = tip_error(cvodes.time, cvodes.tip, chosen.time, chosen.tip)
    assert err.max <= tol
    # on the same samples, the two references differ by at most reference_move
    assert err.max == pytest.approx(choice.reference_error, abs=slack)


def test_slow_light_move_picks_a_low_fidelity(slow):
    scene, choice = slow
    assert choice.choice.modes_per_link is not None and choice.choice.modes_per_link <= 1
    _check_choice(scene, choice, scene.tolerance)
    # the cost ratio is the choice's integration wall time over the reference's, and the choice is
    # cheaper
    ref = choice.evidence["reference"]
    chosen_run = simulate_rung(scene, str(choice.choice), cache=CACHE)
    reference_run = simulate_rung(scene, ref["fidelity"], "rk4", ref["dt_s"], cache=CACHE)
    assert choice.cost_ratio == pytest.approx(
        chosen_run.wall_time_s / reference_run.wall_time_s, rel=1e-12
    )
    assert choice.cost_ratio < 1
    # every rung runs RK4 at the scene's step divided by the smallest whole number k that is stable
    # with the documented margin (omega_max from the model itself), so outputs stay on the scene's
    # grid
    for row in choice.evidence["candidates"]:
        omega = model_for(scene, row["fidelity"], CACHE).omega_max
        k = scene.dt / row["dt_s"]
        assert k == pytest.approx(round(k))
        k = round(k)
        assert omega * row["dt_s"] <= RK4_MARGIN * RK4_LIMIT + 1e-12
        assert k == 1 or omega * scene.dt / (k - 1) > RK4_MARGIN * RK4_LIMIT
    assert any(
        row["dt_s"] < scene.dt for row in choice.evidence["candidates"]
    )  # the rule is exercised


@pytest.mark.slow
def test_fast_heavy_bangbang_needs_more_modes(slow):
    _slow_scene, slow_choice = slow
    scene = load_scene(HEAVY, HEAVY_SET)
    choice = choose_fidelity(scene, scene.tolerance, top=3, cache=CACHE)
    assert choice.choice.modes_per_link > slow_choice.choice.modes_per_link
    _check_choice(
        scene, choice, scene.tolerance
    )  # with the rung below failing the (recomputed) estimate
    assert _rung(choice.choice.modes_per_link - 1) in choice.evidence["ladder"]


def test_choices_are_kept_in_the_callers_cache(slow):
    scene, choice = slow
    again = choose_fidelity(
        load_scene(SLOW, SLOW_SET), scene.tolerance, **SLOW_OPTIONS, cache=CACHE
    )
    assert again is choice
    # so are its runs, which the other checks here reuse: every rung at its step, the reference and
    # its half step
    ref = choice.evidence["reference"]
    made = {(row["fidelity"], row["dt_s"]) for row in choice.evidence["candidates"]}
    made |= {
        (ref["fidelity"], ref["dt_s"]),
        (ref["fidelity"], ref["convergence"]["half_step_run"]["dt_s"]),
    }
    assert SLOW_CHOICE_RUNS["entries"] == len(made)
    before = CACHE.stats()["runs"]["misses"]
    for fidelity, dt in made:
        simulate_rung(scene, fidelity, "rk4", dt, cache=CACHE)
    assert CACHE.stats()["runs"]["misses"] == before
    assert (
        choose_fidelity(
            load_scene(SLOW, SLOW_SET), 2 * scene.tolerance, **SLOW_OPTIONS, cache=CACHE
        )
        is not choice
    )


def test_cli_json_has_the_four_keys(slow, capsys):
    _scene, choice = slow
    argv = [
        "fidelity",
        SLOW,
        "--tol",
        repr(choice.tolerance),
        "--set",
        "duration=1.0",
        "--top",
        "2",
        "--reference",
        "amm:3",
        "--json",
    ]
    assert main(argv) == 0
    data = json.loads(capsys.readouterr().out)
    assert isinstance(data["choice"], str) and parse_fidelity(data["choice"]) == choice.choice
    # the CLI (its own cache, its own runs) reproduces the API's choice: the runs are deterministic
    for key in ("estimated_error", "reference_error", "reference_error_rms"):
        assert data[key] == pytest.approx(getattr(choice, key), rel=1e-9, abs=1e-15)
    assert data["reference"]["fidelity"] == "amm:3"
    assert [c["fidelity"] for c in data["candidates"]] == [
        c["fidelity"] for c in choice.evidence["candidates"]
    ]
    for mine, api in zip(data["candidates"], choice.evidence["candidates"]):
        assert mine["reference_error_max_m"] == pytest.approx(
            api["reference_error_max_m"], rel=1e-9, abs=1e-15
        )
    # the cost ratio is the chosen row's wall time over the reference's (timings differ from the
    # API's run)
    row = next(c for c in data["candidates"] if c["fidelity"] == data["choice"])
    assert data["cost_ratio"] == pytest.approx(
        row["wall_time_s"] / data["reference"]["wall_time_s"], rel=1e-12
    )
    # the table form prints the choice too
    assert main(argv[:-1]) == 0
    assert f"choice {choice.choice}" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, key",
    [
        (["--tol", "0"], "--tol"),
        (["--tol=-1e-3"], "--tol"),
        (["--tol", "nan"], "--tol"),
        (["--set", "tolerance=-1"], "tolerance"),
        (["--set", "fidelity='auto'", "--set", "tolerance=0.0", "--tol", "1e-3"], "tolerance"),
    ],
)
def test_bad_tolerance_exits_2_naming_the_key(argv, key, capsys):
    assert main(["fidelity", SLOW, *argv]) == 2
    err = capsys.readouterr().err
    assert f"key '{key}'" in err and SLOW in err


def test_auto_without_tolerance_is_refused():
    with pytest.raises(SpecError, match="key 'tolerance'.*fidelity = 'auto'"):
        load_scene("studies/scenes/bangbang.toml", ["fidelity='auto'"])


def test_unreachable_tolerance_exits_3_naming_the_best(slow, capsys):
    _scene, choice = slow
    tiny = 0.1 * min(
        c["estimated_error_m"] for c in choice.evidence["candidates"] if "estimated_error_m" in c
    )
    # no rung meets it, so no reference run is made (it only judges a choice): exit 3 with the best
    # estimate
    status = main(
        [
            "fidelity",
            SLOW,
            "--tol",
            repr(tiny),
            "--set",
            "duration=1.0",
            "--top",
            "2",
            "--reference",
            "amm:3",
        ]
    )
    assert status == 3
    err = capsys.readouterr().err
    assert "best estimate" in err and "allowed: a tolerance >=" in err


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
    with pytest.raises(SpecError, match="key 'safety'"):
        choose_fidelity(
            scene, 1e-3, top=2, reference="amm:3", safety=0.5
        )  # below 1: would shrink the estimate
