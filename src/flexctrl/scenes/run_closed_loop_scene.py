"""Running a closed-loop scene (``kind = "closed_loop"``): the loop, its metrics and its files.

A closed-loop scene (:mod:`flexctrl.spec.closed_loop_scene`) names a plant, a
controller file and a move.  :func:`run_closed_loop_scene` builds the loop
(:func:`flexctrl.scenes.loop_setup.build_loop`), runs it
(:mod:`flexctrl.loop.sampled`), measures it (:func:`flexctrl.loop.metrics.run_metrics`)
and writes ``trajectory.csv``, ``summary.json`` and the plots.

Payload mismatch (plant carries one payload, the controller was designed for
another), a controller designed on a coarser model than the plant and one designed
(linearised) at another configuration than the target are scene settings.

A run that leaves the divergence bounds (:mod:`flexctrl.loop.monitors`) stops there:
:func:`run_closed_loop_scene` raises :class:`~flexctrl.errors.SimulationError` naming
the time and the bound (``on_divergence="raise"``, ``flexctrl simulate``), or records it
(``"record"``, the study executor): metrics ``stable = 0`` and ``divergence_time``
(s), the other metrics over the run up to then, so a study row stays ``ok`` and a
stability map is a map of the ``stable`` column.  When the divergence comes before the
residual-vibration window opens, the window is the last plant sample.  Stable runs report
``stable = 1`` and ``divergence_time`` = the scene's duration.  A tip that never settles
into the band reports ``settled = 0`` and ``settling_time`` = the duration (finite:
:func:`flexctrl.loop.metrics.settling_time` gives ``inf``).
"""

from __future__ import annotations

import copy
import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.fidelity.ladder import check_tolerance
from flexctrl.loop.closed_loop import check_on_divergence
from flexctrl.loop.result import ClosedLoopResult, tip_at_rest
from flexctrl.loop.run_summary import judge_run, run_summary
from flexctrl.loop.sampled import simulate_closed_loop, trajectory_from_states
from flexctrl.loop.verdict import linear_closed_loop_radius
from flexctrl.scenes.arm_setup import scene_arm
from flexctrl.scenes.auto_closed_loop import (
    WHOLE_RUNS,
    check_closed_loop_auto,
    choose_closed_loop_fidelity,
    whole_run_key,
)
from flexctrl.scenes.cache import SceneCache
from flexctrl.scenes.loop_setup import LoopSetup, build_loop, pin_design
from flexctrl.sim.rk4 import rk4_step
from flexctrl.spec.fidelity import parse_fidelity


def resolve_auto(
    scene, controller=None, overrides=(), cache: SceneCache | None = None, **options: Any
):
    """For an ``auto`` plant: the scene at the chosen plant fidelity and step, and the choice.

    The design model is pinned first (:func:`pin_design`); the choice is
    :func:`~flexctrl.scenes.auto_closed_loop.choose_closed_loop_fidelity` with the
    scene's ``tolerance`` (kept in ``cache``).  Other scenes come back unchanged with None.
    """
    if scene.plant.fidelity.kind != "auto":
        return scene, None
    scene = pin_design(scene)
    tol = check_tolerance(scene.plant.tolerance, source=scene.source, key="tolerance")
    options.setdefault("walk", scene.plant.fidelity_walk)
    options.setdefault("checks", scene.plant.fidelity_checks)
    choice = choose_closed_loop_fidelity(
        scene, tol, controller=controller, overrides=tuple(overrides), cache=cache, **options
    )
    plant = dataclasses.replace(scene.plant, fidelity=choice.choice, dt=choice.dt)
    return dataclasses.replace(scene, plant=plant), choice


def apply_choice(scene, choice, cache: SceneCache):
    """The auto scene run at a choice made for another run (a study's shared choice).

    The chosen rung, with the RK4 step the chooser's rule gives this scene's own model at
    that rung (:func:`~flexctrl.sim.rk4.rk4_step`).
    """
    scene = pin_design(scene)
    model = cache.model(
        scene_arm(scene.plant), str(choice.choice), scene.plant.modes, scene.plant.q0
    )
    plant = dataclasses.replace(
        scene.plant, fidelity=choice.choice, dt=rk4_step(model.omega_max, scene.plant.dt)
    )
    return dataclasses.replace(scene, plant=plant)


def run_closed_loop_scene(
    scene,
    out: str | Path | None = None,
    *,
    controller=None,
    fidelity=None,
    plots: bool | None = None,
    overrides=(),
    on_divergence: str = "raise",
    auto_options: dict[str, Any] | None = None,
    cache: SceneCache | None = None,
    choice=None,
) -> ClosedLoopResult:
    """Build a closed-loop scene's plant and controller, run it and (with ``out``) write its files.

    Parameters
    ----------
    scene : ClosedLoopScene
        From :func:`flexctrl.load_scene`.
    out : str or Path, optional
        Folder for ``trajectory.csv``, ``summary.json`` (with a ``metrics`` object) and PNGs.
    controller : str or Path or Controller, optional
        Controller file (default: the scene's ``controller``), or a controller designed in
        Python (:func:`flexctrl.design`; see :func:`flexctrl.scenes.loop_setup.build_loop`).
    fidelity : str, optional
        Plant fidelity override (``--fidelity``); ``"auto"`` chooses it (below).
    plots : bool, optional
        Override the scene's ``outputs.plots``.
    overrides : sequence of str
        ``KEY=VALUE`` overrides of the controller file.
    on_divergence : {"raise", "record"}
        What a diverging run does (see the module docstring): raise
        :class:`~flexctrl.errors.SimulationError`, or stop and record ``stable = 0``
        and ``divergence_time`` (s) among the metrics.
    auto_options : dict, optional
        Keywords of :func:`~flexctrl.scenes.auto_closed_loop.choose_closed_loop_fidelity`
        (``top``, ``reference``, ``safety``, ...) for a plant with ``fidelity = "auto"``.
    cache : SceneCache, optional
        Models, designs, verdicts, fidelity runs and choices to reuse (a fresh one when None).
    choice : FidelityChoice, optional
        For a plant with ``fidelity = "auto"``: a choice made for another run (a study's
        shared choice, :mod:`flexctrl.study.shared_choice`) used instead of choosing
        (:func:`apply_choice`); ``choice_time_s`` is then 0.

    Returns
    -------
    ClosedLoopResult
        Its ``summary`` is ``summary.json``'s content; ``files`` what was written.

    Notes
    -----
    With ``fidelity = "auto"`` (scene or override) and the scene's ``tolerance`` (m),
    the controller is designed on ``controller_fidelity`` (default
    :data:`flexctrl.scenes.loop_setup.AUTO_DESIGN_FIDELITY`), the plant fidelity and RK4
    step are chosen by :func:`~flexctrl.scenes.auto_closed_loop.choose_closed_loop_fidelity`
    (kept in ``cache`` by everything that changes the loop), and the run uses them.  The
    summary then holds ``"fidelity_choice"`` (the choice and all its evidence) and the
    metrics ``chosen_modes`` (modes per link of the chosen plant, 0 = rigid), ``chosen_dt``
    (s), ``estimated_error`` and ``reference_error`` (m), ``choice_cost_ratio`` (the
    choice's loop wall time over the reference's) and ``choice_time_s`` (time this call
    spent choosing, s: milliseconds when the choice was cached).
    """
    check_on_divergence(on_divergence)
    requested = _with_fidelity(scene, fidelity)
    cache = SceneCache() if cache is None else cache
    choosing = time.perf_counter()
    scene, choice = _plant_rung(requested, choice, controller, overrides, cache, auto_options)
    choosing = time.perf_counter() - choosing
    setup = build_loop(scene, controller, overrides, cache)
    kept = None if choice is None else _choice_run(setup, requested, controller, overrides, cache)
    trajectory = _run(setup, on_divergence) if kept is None else _from_choice_run(setup, kept)
    result = _result(setup, trajectory, requested, cache)
    if choice is not None:
        _record_choice(result, choice, setup.plant_scene.dt, choosing)
    if out is not None:
        result.save(out, plots=setup.plant_scene.plots if plots is None else plots)
    return result


def _plant_rung(requested, choice, controller, overrides, cache: SceneCache, auto_options):
    """The scene at its plant's rung and the fidelity choice (None for a concrete fidelity).

    An ``auto`` plant takes the shared ``choice`` when given, else chooses (kept in ``cache``).
    """
    if choice is not None and requested.plant.fidelity.kind == "auto":
        return apply_choice(requested, choice, cache), choice
    return resolve_auto(requested, controller, overrides, cache, **(auto_options or {}))


def _with_fidelity(scene, fidelity):
    """The scene with its plant at ``fidelity`` (the ``--fidelity`` override), or unchanged."""
    if fidelity is None:
        return scene
    plant = dataclasses.replace(scene.plant, fidelity=parse_fidelity(fidelity, source="--fidelity"))
    return dataclasses.replace(scene, plant=plant)


def _choice_run(setup: LoopSetup, requested, controller, overrides, cache: SceneCache):
    """The fidelity choice's own run of this scene at the chosen rung and step, if it kept one."""
    key = whole_run_key(
        pin_design(requested),
        str(setup.plant_scene.fidelity),
        setup.plant_scene.dt,
        controller,
        tuple(overrides),
    )
    return cache.take(WHOLE_RUNS, key)


def _from_choice_run(setup: LoopSetup, whole: dict[str, Any]):
    """The trajectory of the chooser's run at the chosen rung (the same run, not repeated)."""
    setup.controller.stats = copy.deepcopy(whole["stats"])
    meta = {
        **whole["meta"],
        "reused": "the fidelity choice's run of this scene at the chosen rung and step",
    }
    return trajectory_from_states(
        setup.plant,
        whole["t"],
        whole["X"].copy(),
        whole["U"].copy(),
        meta,
        compile=setup.plant_scene.solver.get("compile"),
    )


def loop_arguments(setup: LoopSetup) -> dict:
    """The scene's plant, start, duration, step, sensors, noise, compile option and monitor,
    as the keywords of :func:`flexctrl.loop.sampled.integrate_closed_loop` (and
    :func:`~flexctrl.loop.sampled.simulate_closed_loop`) after the controller."""
    scene, plant_scene = setup.scene, setup.plant_scene
    return {
        "plant": setup.plant,
        "x0": setup.x0,
        "duration": plant_scene.duration,
        "dt": plant_scene.dt,
        "sensors": setup.sensors,
        "rng": np.random.default_rng(scene.seed) if scene.noise else None,
        "compile": plant_scene.solver.get("compile"),
        "monitor": setup.monitor,
    }


def _run(setup: LoopSetup, on_divergence: str):
    """The scene's closed loop (:func:`flexctrl.loop.sampled.simulate_closed_loop`)."""
    trajectory, _ = simulate_closed_loop(
        controller=setup.controller,
        **loop_arguments(setup),
        stop_on_divergence=on_divergence == "record",
        plant_changes=setup.changes,
    )
    return trajectory


def _result(setup: LoopSetup, trajectory, requested, cache: SceneCache) -> ClosedLoopResult:
    """The run judged (metrics, linear verdict) and described (``summary.json``)."""
    scene, plant, ctrl = setup.scene, setup.final_plant, setup.controller
    trace = getattr(ctrl, "payload_trace", None)
    tip_target = tip_at_rest(plant, scene.final_q)
    judge = scene.metric_settings
    metrics = judge_run(
        trajectory,
        ctrl,
        setup.reference,
        judge,
        tip_target=tip_target,
        torque_limits=[j.torque_limit for j in setup.arm.joints],
        radius=loop_radius(setup, cache),
        true_payload=_payload_truth(setup),
    )
    summary = {
        "scene": requested.settings(),
        **run_summary(
            trajectory,
            metrics,
            ctrl,
            plant=plant,
            payload=setup.arm.payload.mass,
            design={
                "fidelity": str(setup.design_fidelity),
                "payload_kg": setup.design_arm.payload.mass,
                "configuration_deg": np.degrees(setup.design_q).tolist(),
            },
            path=setup.reference,
            deflection=scene.deflection,
            tip_target=tip_target,
            judge=judge,
            controller_file={"file": None if setup.path is None else str(setup.path)},
        ),
    }
    return ClosedLoopResult(
        trajectory=trajectory,
        metrics=metrics,
        summary=summary,
        model=plant,
        controller=ctrl,
        reference=setup.reference,
        scene=scene,
        payload_estimate=None if trace is None else trace(),
    )


def _record_choice(result: ClosedLoopResult, choice, dt: float, choosing: float) -> None:
    """The fidelity choice's figures among the metrics, and its evidence in the summary."""
    metrics = result.metrics
    metrics["chosen_modes"] = float(choice.choice.count or 0)
    metrics["chosen_dt"] = float(dt)
    metrics["estimated_error"] = float(choice.estimated_error)
    metrics["reference_error"] = float(choice.reference_error)
    metrics["choice_cost_ratio"] = float(choice.cost_ratio)
    metrics["choice_time_s"] = float(choosing)
    result.summary["fidelity_choice"] = choice.to_dict()


def _payload_truth(setup: LoopSetup):
    """The plant's payload (kg), or a function of time (s) when the scene changes it."""
    changes = setup.scene.payload_changes
    if not changes:
        return setup.arm.payload.mass
    times = np.array([t for t, _ in changes])
    masses = np.array([setup.arm.payload.mass] + [m for _, m in changes])
    return lambda t: masses[np.searchsorted(times, np.asarray(t) + 1e-9, side="right")]


def loop_radius(setup, cache: SceneCache) -> float | None:
    """The linear verdict of a set-up loop.

    Kept in ``cache`` ("verdicts") for a controller designed from a file.
    """

    def compute():
        return linear_closed_loop_radius(
            setup.final_plant, setup.controller, setup.scene.final_q, setup.final_sensors
        )

    if setup.design_key is None:
        return compute()
    plant = setup.plant_scene
    key = (
        setup.design_key,
        setup.arm,
        str(plant.fidelity),
        plant.modes,
        plant.q0,
        tuple(setup.scene.final_q),
        setup.scene.payload_changes,
        getattr(setup.controller, "law_key", lambda: None)(),
    )
    return cache.get("verdicts", key, compute)


def check_auto(scene, controller=None) -> None:
    """Refuse, before any run, a closed loop that ``fidelity = "auto"`` cannot choose for.

    Raises
    ------
    SpecError
        Naming the scene file and key: the tolerance (required, > 0 m), the plant's
        integrator (``rk4``), the design model (``controller_fidelity`` not ``auto``)
        or a missing controller.
    """
    check_tolerance(scene.plant.tolerance, source=scene.source, key="tolerance")
    check_closed_loop_auto(scene, controller)
