"""``fidelity_checks = "tolerance"``: a choice that makes only the runs certifying its tolerance.

The walk itself is checked on synthetic runs whose tip paths converge geometrically
with the rung (every walk: from the top, the ladder's from a start, the estimate-first),
counting which rungs and references each walk runs; one closed loop (the small case of
tests/scenes/test_auto_linear.py, MPC from the top) checks the scene key end to end
against the full checks and against distances recomputed from its runs.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from flexctrl.cli import main
from flexctrl.commands.fidelity import format_table
from flexctrl.errors import SpecError
from flexctrl.fidelity.ladder import (
    Ladder,
    Runners,
    RunRecord,
    ToleranceUnreachable,
    tip_distance,
    walk_and_judge,
)
from flexctrl.scenes import auto_closed_loop as auto_fidelity
from flexctrl.scenes.cache import SceneCache
from flexctrl.scenes.loop_setup import pin_design
from flexctrl.scenes.run_arm_scene import resolve_auto as resolve_arm_auto
from flexctrl.scenes.run_closed_loop_scene import resolve_auto
from flexctrl.spec.fidelity import FIDELITY_CHECKS, FIDELITY_WALKS
from flexctrl.spec.scene import load_scene

TIME = np.linspace(0.0, 1.0, 101)


def _record(m: int, *, dt: float = 1e-3, linear: str = "") -> RunRecord:
    """Rung ``m`` (0 = rigid) of a ladder converging as ``2^-m`` mm onto rung 4."""
    tip = np.column_stack([np.cos(TIME), np.sin(TIME)])
    tip[:, 0] += 1e-3 * 2.0**-m * np.sin(7 * TIME) * (m < 4)
    return RunRecord(
        fidelity=f"amm:{m}",
        integrator=linear or "rk4",
        dt=dt,
        omega_max=1.0,
        wall_time_s=0.1,
        build_time_s=0.0,
        time=TIME,
        tip=tip,
    )


def judge(
    *,
    name,
    tol,
    low,
    top,
    reference,
    safety,
    rule,
    run_rung,
    run_reference,
    reference_dt,
    start=None,
    linear=None,
    from_top=False,
    checks="full",
):
    """``walk_and_judge`` with the walk named by what it is given: the linear runs, from the top."""
    walk = "from_top" if from_top else "ladder" if linear is None else "linear_first"
    linear_rung, linear_exact = linear or (None, None)
    return walk_and_judge(
        Ladder(name, tol, low, top, reference, safety, checks),
        Runners(run_rung, run_reference, reference_dt, linear_rung, linear_exact),
        walk=walk,
        start=start,
        rule=rule,
    )


def _walk(checks: str, **kind):
    """``walk_and_judge`` on the synthetic ladder, and what it ran.

    Top ``amm:3``, reference ``amm:4``, tolerance 0.3 mm.
    """
    made: list = []

    def run_rung(m):
        made.append(m)
        return _record(m)

    def run_reference(dt):
        made.append(("reference", dt))
        return _record(4, dt=dt)

    choice = judge(
        name="synthetic",
        tol=3e-4,
        low=0,
        start=kind.pop("start", 3),
        top=3,
        reference="amm:4",
        safety=2.0,
        rule={"excitation_bandwidth_hz": None, "start": "amm:3"},
        run_rung=run_rung,
        run_reference=run_reference,
        reference_dt=1e-4,
        checks=checks,
        **kind,
    )
    return choice, made


def _linear(made: list):
    def linear_rung(m):
        made.append(("linear", m))
        return _record(m, linear="linear-rk4")

    def linear_exact():
        made.append(("linear", "exact"))
        return _record(4, linear="linear-exact")

    return linear_rung, linear_exact


def test_from_the_top_tolerance_stops_at_the_top_and_makes_no_step_check():
    # estimates 2 x the distance to the rungs above: amm:3 0.25 mm, amm:2 0.75 mm (> 0.3 mm)
    made: list = []
    full, full_made = _walk("full", linear=_linear(made), from_top=True)
    assert (
        str(full.choice) == "amm:3" and ("linear", "exact") in made
    )  # full: amm:2 tried, the step checked
    assert sorted(m for m in full_made if isinstance(m, int)) == [2, 3, 4]
    made.clear()
    only, only_made = _walk("tolerance", linear=_linear(made), from_top=True)
    assert str(only.choice) == "amm:3" and sorted(only_made) == [3, 4] and made == []
    assert (
        only.estimated_error == full.estimated_error == pytest.approx(2 * 1e-3 * 2.0**-3, rel=1e-2)
    )
    assert only.evidence["checks"] == "tolerance" and full.evidence["checks"] == "full"
    convergence = only.evidence["reference"]["convergence"]
    assert "step_error_linear_m" not in convergence and "not made" in convergence["step_check"]
    assert (
        convergence["rung_below_m"] == tip_distance(_record(4), _record(3)).max
    )  # amm:3 was run anyway


def test_tolerance_keeps_a_higher_rung_where_full_finds_a_lower_one():
    # with 1 mm every rung from amm:1 up meets: full walks down to it; tolerance keeps the top it
    # started from
    made: list = []
    kw = dict(
        tol=1e-3,
        low=0,
        top=3,
        reference="amm:4",
        safety=2.0,
        rule={},
        reference_dt=1e-4,
        name="synthetic",
        run_rung=lambda m: (made.append(m), _record(m))[1],
        run_reference=lambda dt: _record(4, dt=dt),
    )
    full = judge(**kw, start=3, linear=_linear([]), from_top=True)
    made.clear()
    only = judge(**kw, start=3, linear=_linear([]), from_top=True, checks="tolerance")
    assert str(full.choice) == "amm:1" and str(only.choice) == "amm:3" and sorted(made) == [3, 4]
    assert only.estimated_error <= 1e-3 and only.reference_error <= only.estimated_error


def test_ladder_walk_tolerance_makes_no_half_step_reference_and_no_walk_down():
    full, full_made = _walk("full", start=3)
    only, only_made = _walk("tolerance", start=3)
    assert ("reference", 5e-5) in full_made and [m for m in only_made if isinstance(m, tuple)] == [
        ("reference", 1e-4)
    ]
    assert 2 in full_made and 2 not in only_made
    assert "step_halving_m" in full.evidence["reference"]["convergence"]
    assert "step_halving_m" not in only.evidence["reference"]["convergence"]
    # from a start below the choice the walk goes up in both: the estimates decide, not the checks
    up, up_made = _walk("tolerance", start=1)
    assert str(up.choice) == "amm:3" and {1, 2, 3, 4} <= set(up_made)


def test_estimate_first_walk_keeps_its_candidate_and_drops_only_the_step_check():
    made: list = []
    full, _ = _walk("full", linear=_linear(made))
    full_linear = list(made)
    made.clear()
    only, _ = _walk("tolerance", linear=_linear(made))
    assert str(only.choice) == str(full.choice) and only.estimated_error == full.estimated_error
    # the full walk's last two linear runs are its step check: the exact loop and the reference's at
    # its step
    assert full_linear[-2:] == [("linear", "exact"), ("linear", 4)] and made == full_linear[:-2]


def test_a_bad_value_is_refused_naming_the_key_and_the_values_allowed():
    with pytest.raises(SpecError, match="fidelity_checks") as bad:
        load_scene("studies/scenes/move_joint1_30deg.toml", ["fidelity_checks='some'"])
    assert all(repr(value) in str(bad.value) for value in FIDELITY_CHECKS) and "'some'" in str(
        bad.value
    )
    scene = pin_design(
        load_scene("studies/scenes/move_joint1_30deg.toml", ["fidelity='auto'", "tolerance=1e-2"])
    )
    with pytest.raises(SpecError, match="fidelity_checks"):
        auto_fidelity.choose_closed_loop_fidelity(scene, 1e-2, checks="none")
    with pytest.raises(ValueError, match="checks"):
        _walk("none")


def test_the_walks_are_estimate_and_ladder():
    assert FIDELITY_WALKS == ("estimate", "ladder")
    with pytest.raises(SpecError, match="fidelity_walk.*'linear'.*allowed: 'estimate', 'ladder'"):
        load_scene("studies/scenes/move_joint1_30deg.toml", ["fidelity_walk='linear'"])
    scene = pin_design(
        load_scene("studies/scenes/move_joint1_30deg.toml", ["fidelity='auto'", "tolerance=1e-2"])
    )
    with pytest.raises(SpecError, match="fidelity_walk"):
        auto_fidelity.choose_closed_loop_fidelity(scene, 1e-2, walk="linear")


def test_the_scene_key_reaches_a_closed_loops_choice_and_only_the_certifying_runs_are_made():
    short = [
        "duration=2.8",
        "initial.q=[0.0, 90.0, -90.0]",
        "fidelity='auto'",
        "tolerance=1e-2",
        "controller_fidelity='amm:2'",
    ]
    mpc, options = "controllers/mpc.toml", {"top": 3, "reference": "amm:4"}
    full_cache, cache = SceneCache(), SceneCache()
    _, full = resolve_auto(
        pin_design(load_scene("studies/scenes/move_joint1_30deg.toml", short)),
        mpc,
        cache=full_cache,
        **options,
    )
    scene = pin_design(
        load_scene("studies/scenes/move_joint1_30deg.toml", [*short, "fidelity_checks='tolerance'"])
    )
    _, only = resolve_auto(scene, mpc, cache=cache, **options)
    assert only.evidence["checks"] == "tolerance" and full.evidence["checks"] == "full"
    assert (
        str(full.choice) == "amm:2" and str(only.choice) == "amm:3"
    )  # full finds the lower rung that also meets
    assert cache.stats()["closed_runs"]["misses"] == 2 and "linear_runs" not in cache.stats()
    assert (
        full_cache.stats()["closed_runs"]["misses"] == 4
        and full_cache.stats()["linear_runs"]["misses"] == 1
    )
    # the choices are kept apart by what they check; the runs are shared (no new run)
    _, again = resolve_auto(
        pin_design(load_scene("studies/scenes/move_joint1_30deg.toml", short)),
        mpc,
        cache=cache,
        **options,
    )
    assert str(again.choice) == "amm:2" and again.estimated_error == full.estimated_error
    assert cache.stats()["closed_runs"]["misses"] == 4  # amm:1 and amm:2 added for the full walk
    # the certificate recomputed from the full walk's runs (the same runs, to the last digit)
    ref = auto_fidelity.simulate_closed_rung(scene, "amm:4", controller=mpc, cache=full_cache)
    at3 = auto_fidelity.simulate_closed_rung(scene, "amm:3", controller=mpc, cache=full_cache)
    assert only.estimated_error == 2.0 * tip_distance(ref, at3).max <= 1e-2
    assert only.reference_error == tip_distance(ref, at3).max


def test_tolerance_runs_the_rung_below_the_reference_only_when_the_walk_ran_it():
    # reference amm:6: a choice of amm:2 is estimated from amm:3 and amm:4, so the rung below
    # (amm:5) is no run of it
    made: list = []
    kw = dict(
        tol=1e-3,
        low=0,
        start=2,
        top=3,
        reference="amm:6",
        safety=2.0,
        rule={},
        reference_dt=1e-4,
        name="synthetic",
        run_rung=lambda m: (made.append(m), _record(m))[1],
        run_reference=lambda dt: _record(4, dt=dt),
    )
    full = judge(**kw)
    assert str(full.choice) == "amm:1" and 5 in made
    assert (
        full.evidence["reference"]["convergence"]["rung_below_m"] == 0.0
    )  # amm:5 follows the reference's path
    made.clear()
    only = judge(**kw, checks="tolerance")
    # neither the rung below the reference nor the finest model at its own step (the ladder walk's
    # cost evidence)
    assert str(only.choice) == "amm:2" and sorted(made) == [2, 3, 4]
    assert only.evidence["reference"]["convergence"]["rung_below_m"] is None
    assert (
        only.evidence["cost_ratio_vs_finest"] is None
        and full.evidence["cost_ratio_vs_finest"] == 1.0
    )


@pytest.mark.parametrize(
    "kind", [{"start": 3}, {"from_top": True}, {}], ids=["ladder", "from_top", "estimate"]
)
def test_the_table_says_which_checks_were_not_made(kind):
    linear = {} if kind.get("start") else {"linear": _linear([])}
    only, _ = _walk("tolerance", **kind, **linear)
    full, _ = _walk("full", **kind, **linear)
    text = format_table(only.to_dict())
    assert (
        "step check not made (fidelity_checks = 'tolerance')" in text
        and f"choice {only.choice}" in text
    )
    assert "not made" not in format_table(full.to_dict()) and "not run" not in format_table(
        full.to_dict()
    )


def test_in_tolerance_mode_a_convergence_warning_names_only_the_check_made():
    # amm:3 is 0.125 mm from the reference amm:4, above half of a 0.2 mm tolerance: the reference
    # may not be converged
    kw = dict(
        tol=2e-4,
        low=0,
        start=3,
        top=3,
        reference="amm:4",
        safety=1.0,
        rule={},
        reference_dt=1e-4,
        name="synthetic",
        run_rung=_record,
        run_reference=lambda dt: _record(4, dt=dt),
    )
    with pytest.warns(UserWarning, match="moves by .* with half its step and differs by"):
        judge(**kw)
    with pytest.warns(
        UserWarning, match=r"\(rk4, dt = 0.0001 s\) differs by 0.000125 m from amm:3"
    ) as caught:
        judge(**kw, checks="tolerance")
    assert not any("moves by" in str(w.message) for w in caught)


def test_a_predicted_failure_records_the_checks_asked_for():
    def far(m):
        return _record(m, linear="linear-rk4") if m < 4 else _record(4, linear="linear-rk4")

    with pytest.raises(ToleranceUnreachable) as failed:
        judge(
            name="synthetic",
            tol=1e-6,
            low=0,
            start=3,
            top=3,
            reference="amm:4",
            safety=2.0,
            rule={},
            run_rung=_record,
            run_reference=lambda dt: _record(4, dt=dt),
            reference_dt=1e-4,
            linear=(far, lambda: _record(4)),
            checks="tolerance",
        )
    assert failed.value.evidence["predicted"] and failed.value.evidence["checks"] == "tolerance"


def test_an_arm_scene_reads_the_key_through_the_command_and_the_scene(capsys):
    # the slow light move of tests/scenes/test_auto_arm_fidelity.py: the ladder walk, rungs up to
    # amm:2 against amm:3
    argv = [
        "fidelity",
        "studies/scenes/slow_move_light.toml",
        "--tol",
        "1e-3",
        "--set",
        "duration=1.0",
        "--top",
        "2",
        "--reference",
        "amm:3",
    ]
    assert main([*argv, "--json"]) == 0
    full = json.loads(capsys.readouterr().out)
    assert main([*argv, "--set", "fidelity_checks='tolerance'", "--json"]) == 0
    only = json.loads(capsys.readouterr().out)
    assert full["checks"] == "full" and only["checks"] == "tolerance"
    assert (
        "step_halving_m" in full["reference"]["convergence"]
        and "step_check" in only["reference"]["convergence"]
    )
    assert len(only["candidates"]) < len(
        full["candidates"]
    )  # full walks down to the lowest rung that meets
    assert main([*argv, "--set", "fidelity_checks='tolerance'"]) == 0
    assert "step check not made" in capsys.readouterr().out
    # the scene's own resolution (kind = "arm"), with the choices of the two modes kept apart in one
    # cache
    cache = SceneCache()
    scenes = [
        load_scene(
            "studies/scenes/slow_move_light.toml",
            ["duration=1.0", "fidelity='auto'", "tolerance=1e-3", *extra],
        )
        for extra in ([], ["fidelity_checks='tolerance'"])
    ]
    _, by_full = resolve_arm_auto(scenes[0], cache=cache, top=2, reference="amm:3")
    _, by_only = resolve_arm_auto(scenes[1], cache=cache, top=2, reference="amm:3")
    assert by_full.evidence["checks"] == "full" and by_only.evidence["checks"] == "tolerance"
    assert str(by_full.choice) == full["choice"] and str(by_only.choice) == only["choice"]
