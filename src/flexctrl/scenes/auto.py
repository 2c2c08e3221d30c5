"""Running scenes for the automatic-fidelity ladder (:mod:`flexctrl.fidelity.ladder`).

The ladder's method is pure: it judges runs it is handed.  This module makes those
runs: an arm scene at a rung (:func:`simulate_rung`), a closed loop with the plant at
a rung (:func:`simulate_closed_rung`), and the two choosers that connect them to
:func:`~flexctrl.fidelity.ladder.walk_and_judge`: :func:`choose_fidelity` (``kind =
"arm"``) and :func:`choose_closed_loop_fidelity` (``kind = "closed_loop"``).

Models, set-up integrators, runs and whole choices are kept in the
:class:`~flexctrl.scenes.cache.SceneCache` the caller passes (``cache=``), keyed by
everything that changes them (:func:`scene_key`, :func:`closed_loop_key`), so a study
running one scene many times on one cache chooses once.  Without a cache, a fresh one
serves the call.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path
from typing import Any

from flexctrl.errors import SpecError
from flexctrl.fidelity.ladder import (
    IMPLICIT,
    LINEAR_FACTOR,
    WALKS,
    FidelityChoice,
    RunRecord,
    check_ladder,
    check_tolerance,
    excitation_bandwidth,
    required_modes,
    rung_name,
    sampled_bandwidth,
    walk_and_judge,
)
from flexctrl.scenes.arm_setup import scene_arm, simulate_arm_scene
from flexctrl.scenes.cache import SceneCache, read_only
from flexctrl.scenes.loop_setup import AUTO_DESIGN_FIDELITY, closed_loop_tip_path
from flexctrl.sim.rk4 import rk4_step
from flexctrl.spec.fidelity import FIDELITY_CHECKS, Fidelity, parse_fidelity


def scene_key(scene) -> str:
    """A canonical string of everything in an arm scene that changes its simulation (not its fidelity)."""
    settings = scene.settings()
    for name in (
        "fidelity",
        "tolerance_m",
        "fidelity_walk",
        "fidelity_checks",
        "name",
        "source",
        "fft_span",
        "fft_peaks",
    ):
        settings.pop(name, None)
    path = Path(scene.model)
    settings["model_mtime_ns"] = path.stat().st_mtime_ns if path.is_file() else None
    return json.dumps(settings, sort_keys=True, default=str)


# -- caches ---------------------------------------------------------------------------------
def _run_settings(scene, model) -> tuple[str, float]:
    """Integrator and step for a rung (method step 4 of :mod:`flexctrl.fidelity.ladder`)."""
    if scene.integrator in IMPLICIT:
        return scene.integrator, scene.dt
    return "rk4", rk4_step(model.omega_max, scene.dt)


def model_for(scene, fidelity: str, cache: SceneCache):
    """The arm scene's model at ``fidelity``, from ``cache``."""
    return cache.model(scene_arm(scene), fidelity, scene.modes, scene.q0)


def simulate_rung(
    scene,
    fidelity: str,
    integrator: str | None = None,
    dt: float | None = None,
    *,
    cache: SceneCache | None = None,
) -> RunRecord:
    """Simulate ``scene`` at ``fidelity``; the integrator and step default to method step 4.

    Raises
    ------
    SimulationError
        If the run diverges.
    """
    cache = SceneCache() if cache is None else cache
    model = model_for(scene, fidelity, cache)
    if integrator is None or dt is None:
        integrator, dt = _run_settings(scene, model)
    key = (scene_key(scene), fidelity, integrator, float(dt))
    return cache.get(
        "runs", key, lambda: _simulate_rung(scene, fidelity, integrator, float(dt), cache)
    )


def _simulate_rung(
    scene, fidelity: str, integrator: str, dt: float, cache: SceneCache
) -> RunRecord:
    start = time.perf_counter()
    model = model_for(scene, fidelity, cache)
    solver = {k: v for k, v in scene.solver.items() if integrator == scene.integrator}
    built, _setup = cache.integrator(
        scene_arm(scene),
        fidelity,
        scene.modes,
        scene.q0,
        integrator,
        dt,
        tuple(sorted(solver.items())),
    )
    build = time.perf_counter() - start
    run_scene = dataclasses.replace(
        scene, fidelity=parse_fidelity(fidelity), integrator=integrator, dt=dt
    )
    trajectory, model, _arm = simulate_arm_scene(run_scene, model=model, integrator=built)
    times, tip = read_only(trajectory.time.copy(), trajectory.tip.copy())
    return RunRecord(
        fidelity=fidelity,
        integrator=integrator,
        dt=dt,
        omega_max=float(model.omega_max),
        wall_time_s=float(trajectory.meta["wall_time_s"]),
        build_time_s=build,
        time=times,
        tip=tip,
    )


def prepared(scene, cache: SceneCache) -> tuple[Any, Any]:
    """The cached model and set-up integrator for a scene at a concrete fidelity, integrator and step.

    Used to run a scene that ``fidelity = "auto"`` resolved: the chooser has built both already.
    """
    solver = tuple(sorted(scene.solver.items()))
    integrator, _setup = cache.integrator(
        scene_arm(scene),
        str(scene.fidelity),
        scene.modes,
        scene.q0,
        scene.integrator,
        float(scene.dt),
        solver,
    )
    return integrator.model, integrator


def choose_fidelity(
    scene,
    tol: float,
    *,
    top: int = 4,
    reference: str | Fidelity | None = None,
    safety: float = 2.0,
    energy_fraction: float = 0.99,
    bandwidth_factor: float = 5.0,
    reference_omega_dt: float = 0.5,
    cache: SceneCache | None = None,
    checks: str = "full",
) -> FidelityChoice:
    """The lowest rung of ``rigid, amm:1 .. amm:top`` estimated to keep the tip within ``tol`` (see module docstring).

    Parameters
    ----------
    scene : ArmScene
        A ``kind = "arm"`` scene (its fidelity is ignored); a closed-loop scene's ``plant`` is not accepted.
    tol : float
        Tolerance on the largest tip-position error (m), > 0.
    top : int
        Highest candidate rung (``amm:top``), 1..5.
    reference : str or Fidelity, optional
        The reference model, ``amm:R`` with ``top < R <= 6``; default ``amm:(top + 1)``.
    safety : float
        Factor (>= 1) on the distance to the next rung that makes the error estimate.
    energy_fraction : float
        Share of the torque energy that defines the excitation bandwidth, in (0, 1).
    bandwidth_factor : float
        Modes below ``bandwidth_factor`` times the bandwidth are kept by the starting rung (> 0).
    reference_omega_dt : float
        ``omega_max * dt`` of the reference's RK4 step (0 < value <= 2.5).
    cache : SceneCache, optional
        Where models, runs and the choice are kept (a fresh one when None).
    checks : {"full", "tolerance"}
        What is checked beyond the tolerance (:func:`~flexctrl.fidelity.ladder.walk_and_judge`).

    Returns
    -------
    FidelityChoice

    Raises
    ------
    SpecError
        For a bad tolerance or option (naming it, its value and what is allowed).
    ToleranceUnreachable
        When no candidate's estimate meets ``tol`` (naming the best achievable).
    SimulationError
        If a run diverges.
    """
    tol = check_tolerance(tol, key="tolerance")
    if getattr(scene, "kind", None) != "arm":
        raise SpecError(
            f"scene kind '{getattr(scene, 'kind', type(scene).__name__)}' is not supported; allowed: a kind = \"arm\" scene",
            source=getattr(scene, "source", None),
            key="kind",
        )
    ref = check_ladder(
        top, reference, safety, energy_fraction, bandwidth_factor, reference_omega_dt
    )
    check_checks(checks, scene.source)
    cache = SceneCache() if cache is None else cache
    options = (
        tol,
        top,
        str(ref),
        float(safety),
        float(energy_fraction),
        float(bandwidth_factor),
        float(reference_omega_dt),
        checks,
    )
    return cache.get(
        "choices", (scene_key(scene), options), lambda: _choose(scene, cache, *options)
    )


def check_checks(checks, source) -> None:
    """:class:`SpecError` unless ``checks`` is one of ``FIDELITY_CHECKS`` (the scene key ``fidelity_checks``)."""
    if checks not in FIDELITY_CHECKS:
        raise SpecError(
            f"value {checks!r} is not allowed; allowed: {', '.join(map(repr, FIDELITY_CHECKS))}",
            source=source,
            key="fidelity_checks",
        )


def _choose(
    scene,
    cache: SceneCache,
    tol: float,
    top: int,
    reference: str,
    safety: float,
    energy_fraction: float,
    bandwidth_factor: float,
    reference_omega_dt: float,
    checks: str,
) -> FidelityChoice:
    ref_n = parse_fidelity(reference).count
    low = required_modes(scene)
    if low > top:
        raise SpecError(
            f"the initial elastic coordinates need {low} modes per link, above the top candidate amm:{top}; "
            f"allowed: top >= {low}",
            source=scene.source,
            key="initial.qf",
        )

    # (a) the modal-bandwidth rule, on the finest model's per-link mode frequencies
    top_model = model_for(scene, reference, cache)
    n_joints = top_model.n_joints
    bandwidth = excitation_bandwidth(scene, n_joints, energy_fraction=energy_fraction)
    link_hz = [
        [w / (2 * math.pi) for w in link]
        for link in top_model.info.get("link_frequencies_rad_s", [])
    ]
    if bandwidth is None:
        start = low
        kept = None
    else:
        limit = bandwidth_factor * bandwidth
        kept = [sum(1 for f in link if f <= limit) for link in link_hz]
        start = min(max([low, *kept]), top)
    rule = {
        "excitation_bandwidth_hz": bandwidth,
        "energy_fraction": energy_fraction,
        "factor": bandwidth_factor,
        "cutoff_hz": None if bandwidth is None else bandwidth_factor * bandwidth,
        "link_mode_frequencies_hz": link_hz,
        "modes_kept_per_link": kept,
        "start": rung_name(start),
        "lowest_rung_for_initial_state": rung_name(low),
    }

    ref_model = model_for(scene, reference, cache)
    ref_dt = scene.dt / max(
        1, math.ceil(scene.dt * ref_model.omega_max / reference_omega_dt - 1e-12)
    )
    return walk_and_judge(
        name=scene.name,
        tol=tol,
        low=low,
        start=start,
        top=top,
        reference=reference,
        safety=safety,
        rule=rule,
        run_rung=lambda m: simulate_rung(scene, rung_name(m), cache=cache),
        run_reference=lambda dt: simulate_rung(scene, reference, "rk4", dt, cache=cache),
        reference_dt=ref_dt,
        checks=checks,
    )


def controller_digest(path: str | Path) -> str:
    """sha256 of a controller file's bytes (hex)."""
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def closed_loop_key(
    scene, controller: str | Path | None = None, overrides: tuple[str, ...] = ()
) -> str:
    """A canonical string of everything that changes a closed loop's simulation except the plant fidelity.

    The scene's settings (plant, payload, initial configuration, target, reference,
    design payload / fidelity / configuration, noise and seed, metrics windows), the
    model file's modification time, the controller file's path, sha256 and overrides.
    """
    settings = scene.settings()
    for name in (
        "fidelity",
        "tolerance_m",
        "fidelity_walk",
        "fidelity_checks",
        "name",
        "source",
        "fft_span",
        "fft_peaks",
        "controller",
    ):
        settings.pop(name, None)
    path = Path(scene.plant.model)
    settings["model_mtime_ns"] = path.stat().st_mtime_ns if path.is_file() else None
    ctrl = controller or scene.controller
    settings["controller_file"] = None if ctrl is None else str(Path(ctrl).resolve())
    settings["controller_sha256"] = (
        None if ctrl is None or not Path(ctrl).is_file() else controller_digest(ctrl)
    )
    settings["controller_overrides"] = list(overrides)
    return json.dumps(settings, sort_keys=True, default=str)


def simulate_closed_rung(
    scene,
    fidelity: str,
    dt: float | None = None,
    *,
    controller: str | Path | None = None,
    overrides: tuple[str, ...] = (),
    cache: SceneCache | None = None,
) -> RunRecord:
    """The closed loop with the plant at ``fidelity`` and RK4 step ``dt`` (s; default method step 4).

    The tip is kept on the scene's grid (every ``scene.dt / dt``-th plant sample), so
    every rung is compared on the same times without interpolation.  A run at the rung's
    own step (``dt`` None) also leaves the whole run in ``cache`` (:data:`WHOLE_RUNS`,
    :func:`whole_run_key`) for the run of the scene at the chosen rung to reuse.
    """
    cache = SceneCache() if cache is None else cache
    own = dt is None
    if dt is None:
        dt = rk4_step(model_for(scene.plant, fidelity, cache).omega_max, scene.plant.dt)
    dt = float(dt)
    key = whole_run_key(scene, fidelity, dt, controller, overrides)

    def run() -> RunRecord:
        stride = int(round(scene.plant.dt / dt))
        result = closed_loop_tip_path(
            scene,
            fidelity,
            dt,
            controller=controller,
            overrides=overrides,
            stride=stride,
            cache=cache,
            keep=own,
        )
        if own:
            cache.keep(WHOLE_RUNS, key, result["run"], limit=WHOLE_RUNS_KEPT)
        times, tip, torque = read_only(result["time"], result["tip"], result["torque"])
        return RunRecord(
            fidelity=fidelity,
            integrator="rk4",
            dt=dt,
            omega_max=result["omega_max"],
            wall_time_s=result["wall_time_s"],
            build_time_s=result["build_time_s"],
            time=times,
            tip=tip,
            diverged_at=result["diverged_at"],
            torque=torque,
        )

    return cache.get("closed_runs", key, run)


#: The cache's kind for whole closed-loop runs at a rung's own step, kept for one reuse; at most this many.
WHOLE_RUNS, WHOLE_RUNS_KEPT = "whole_closed_runs", 8


def whole_run_key(
    scene, fidelity: str, dt: float, controller=None, overrides: tuple[str, ...] = ()
) -> tuple:
    """The key of :data:`WHOLE_RUNS`: the chooser's scene (design pinned), the rung and its RK4 step (s)."""
    return (closed_loop_key(scene, controller, tuple(overrides)), str(fidelity), float(dt))


def check_closed_loop_auto(scene, controller=None) -> None:
    """Refuse a closed loop whose plant ``fidelity = "auto"`` cannot choose (the tolerance is checked apart).

    Raises
    ------
    SpecError
        Naming the scene file and key: the plant's integrator (``rk4``), the design model
        (``controller_fidelity`` not ``auto``) or a missing controller.
    """
    if scene.plant.integrator != "rk4":
        raise SpecError(
            f"value '{scene.plant.integrator}' is not allowed with fidelity = 'auto' in a closed loop; "
            "allowed: 'rk4' (the loop integrates the plant with RK4)",
            source=scene.source,
            key="integrator",
        )
    if scene.controller_fidelity is not None and scene.controller_fidelity.kind == "auto":
        raise SpecError(
            "value 'auto' is not allowed for the design model; allowed: 'rigid', 'amm:N' or 'fem:N' "
            f"(default {AUTO_DESIGN_FIDELITY!r} when the plant is auto)",
            source=scene.source,
            key="controller_fidelity",
        )
    if (controller or scene.controller) is None:
        raise SpecError(
            "no controller: give --controller FILE or the scene key 'controller'",
            source=scene.source,
            key="controller",
        )


def choose_closed_loop_fidelity(
    scene,
    tol: float,
    *,
    controller: str | Path | None = None,
    overrides: tuple[str, ...] | list[str] = (),
    top: int = 4,
    reference: str | Fidelity | None = None,
    safety: float = 2.0,
    energy_fraction: float = 0.99,
    bandwidth_factor: float = 5.0,
    reference_omega_dt: float = 0.5,
    cache: SceneCache | None = None,
    walk: str = "estimate",
    checks: str = "full",
) -> FidelityChoice:
    """The lowest plant rung of ``rigid, amm:1 .. amm:top`` estimated to keep a closed loop's tip within ``tol``.

    As :func:`choose_fidelity`, with every candidate a whole closed-loop run: the
    controller (the scene's or ``controller`` with ``overrides``) designed on the
    scene's ``controller_fidelity`` (pinned: the plant's fidelity is what is chosen;
    :func:`flexctrl.scenes.run_closed_loop_scene.pin_design` gives ``amm:2`` when the scene names none),
    its payload and configuration, the same for every rung; the plant at the rung, RK4
    at the rung's step (the scene's ``dt`` divided by the smallest whole number that
    makes ``omega_max * dt <= 0.9 * 2.785``).  Differences from the arm method:

    * The excitation is the controller's torque, known only by running the loop, so
      the bandwidth rule (method step 1) reads the torques of a first run with the
      plant at the design model's rung (clipped to the ladder), with their mean
      removed; the walk then starts where the rule says.
    * Tip paths are compared on the scene's grid (``dt``), where every rung and the
      reference have samples (their steps divide it), not at every plant step.
    * A candidate whose loop diverges has an infinite distance (it cannot be chosen);
      a diverging reference raises :class:`~flexctrl.errors.SimulationError`.

    Parameters
    ----------
    scene : ClosedLoopScene
        Its plant's fidelity is ignored; ``controller_fidelity`` must be set (see
        :func:`flexctrl.scenes.run_closed_loop_scene.pin_design`).
    tol : float
        Tolerance on the largest tip-position distance (m), > 0.
    controller : str or Path, optional
        Controller file (default: the scene's ``controller``).
    overrides : sequence of str
        ``KEY=VALUE`` overrides of the controller file.
    top, reference, safety, energy_fraction, bandwidth_factor, reference_omega_dt
        As in :func:`choose_fidelity`.
    cache : SceneCache, optional
        Where models, runs and the choice are kept (a fresh one when None).
    walk : {"estimate", "ladder"}
        ``estimate`` (default), for a controller with a sampled law (``has_sampled_law``:
        the linear loop is one compiled call): every rung's loop first on its linearised
        plant (:mod:`flexctrl.scenes.auto_linear`); the lowest rung whose linear estimate is
        within :data:`~flexctrl.fidelity.ladder.LINEAR_FACTOR` of the tolerance is
        certified by the nonlinear runs of the estimate's formula, walking up while it
        fails; no rung within the factor is a predicted :class:`ToleranceUnreachable`
        without nonlinear runs.  For a controller stepped in Python (MPC, NMPC, a gain
        schedule), whose linear run costs what its nonlinear run does, no linear estimate
        of the rungs: the nonlinear walk from ``top`` down while the rung below meets the
        tolerance.  Either way the reference is the reference model at its own step, its
        step error estimated linearly.  ``ladder``: nonlinear runs only, from the bandwidth
        rule's start, the reference at ``reference_omega_dt`` and half its step: no linear
        assumption (for a loop the linearisation at the target does not describe), at
        several times the cost.
    checks : {"full", "tolerance"}
        What is checked beyond the tolerance (:func:`~flexctrl.fidelity.ladder.walk_and_judge`):
        ``tolerance`` makes only the runs that certify it (no rung below a rung that meets
        it is tried, no step check of the reference).

    Returns
    -------
    FidelityChoice
        ``integrator`` is ``"rk4"`` and ``dt`` the plant step (s) to run the choice with.

    Raises
    ------
    SpecError
        Bad tolerance, option, or a scene without controller or ``controller_fidelity``.
    ToleranceUnreachable
        When no candidate's estimate meets ``tol``.
    SimulationError
        When the reference loop diverges.
    """
    tol = check_tolerance(tol, key="tolerance")
    if getattr(scene, "kind", None) != "closed_loop":
        raise SpecError(
            f"scene kind '{getattr(scene, 'kind', type(scene).__name__)}' is not supported here; allowed: "
            'a kind = "closed_loop" scene (choose_fidelity takes arm scenes)',
            source=getattr(scene, "source", None),
            key="kind",
        )
    if scene.controller_fidelity is None:
        raise SpecError(
            "value None is not allowed when the plant is chosen; allowed: a concrete design model, e.g. "
            f"{AUTO_DESIGN_FIDELITY!r} (flexctrl.scenes.loop_setup.pin_design sets the default)",
            source=scene.source,
            key="controller_fidelity",
        )
    check_closed_loop_auto(scene, controller)
    if walk not in WALKS:
        raise SpecError(
            f"value {walk!r} is not allowed; allowed: {', '.join(map(repr, WALKS))}",
            source=scene.source,
            key="fidelity_walk",
        )
    ref = check_ladder(
        top, reference, safety, energy_fraction, bandwidth_factor, reference_omega_dt
    )
    check_checks(checks, scene.source)
    cache = SceneCache() if cache is None else cache
    overrides = tuple(overrides)
    options = (
        tol,
        top,
        str(ref),
        float(safety),
        float(energy_fraction),
        float(bandwidth_factor),
        float(reference_omega_dt),
        walk,
        checks,
    )
    key = (closed_loop_key(scene, controller, overrides), options)
    return cache.get(
        "closed_choices", key, lambda: _choose_closed(scene, controller, overrides, cache, *options)
    )


def _choose_closed(
    scene,
    controller,
    overrides: tuple[str, ...],
    cache: SceneCache,
    tol: float,
    top: int,
    reference: str,
    safety: float,
    energy_fraction: float,
    bandwidth_factor: float,
    reference_omega_dt: float,
    walk: str,
    checks: str,
) -> FidelityChoice:
    started = time.perf_counter()
    plant = scene.plant
    low = required_modes(plant)
    if low > top:
        raise SpecError(
            f"the initial elastic coordinates need {low} modes per link, above the top candidate amm:{top}; "
            f"allowed: top >= {low}",
            source=scene.source,
            key="initial.qf",
        )
    design = scene.controller_fidelity

    def rung(m: int) -> RunRecord:
        return simulate_closed_rung(
            scene, rung_name(m), controller=controller, overrides=overrides, cache=cache
        )

    design_rung = (
        0 if design.kind == "rigid" else (design.count or 0) if design.kind == "amm" else top
    )
    first = min(max(low, design_rung), top)
    linear, from_top = None, False
    if walk == "estimate":
        from flexctrl.scenes.auto_linear import linear_closed_rung, loop_at

        def linear_rung(m: int) -> RunRecord:
            h = rk4_step(model_for(plant, rung_name(m), cache).omega_max, plant.dt)
            return cache.get(
                "linear_runs",
                (closed_loop_key(scene, controller, overrides), rung_name(m), h),
                lambda: linear_closed_rung(
                    scene, rung_name(m), h, controller=controller, overrides=overrides, cache=cache
                ),
            )

        linear = (
            linear_rung,
            lambda: linear_closed_rung(
                scene, reference, None, controller=controller, overrides=overrides, cache=cache
            ),
        )
        # a controller stepped in Python costs as much on a linear plant as on the nonlinear one: no linear
        # estimate of the rungs, the nonlinear walk from the top down (the step check stays linear)
        from_top = not loop_at(
            scene, rung_name(first), controller, overrides, cache
        ).controller.has_sampled_law()
    if from_top:
        runs = {top: rung(top)}
        record = runs[top]
    elif (
        linear is not None
    ):  # the linear runs give the torques: no nonlinear run before the candidate is known
        runs, record = {}, linear[0](first)
    else:
        runs = {first: rung(first)}
        record = runs[first]
    ref_model = model_for(plant, reference, cache)
    link_hz = [
        [w / (2 * math.pi) for w in link]
        for link in ref_model.info.get("link_frequencies_rad_s", [])
    ]
    bandwidth = None
    if record.torque is not None and record.diverged_at is None and record.time.size > 2:
        bandwidth = sampled_bandwidth(
            record.torque, float(record.time[1] - record.time[0]), energy_fraction=energy_fraction
        )
    if bandwidth is None:
        start, kept = first, None
    else:
        limit = bandwidth_factor * bandwidth
        kept = [sum(1 for f in link if f <= limit) for link in link_hz]
        start = min(max([low, *kept]), top)
    rule = {
        "excitation_bandwidth_hz": bandwidth,
        "energy_fraction": energy_fraction,
        "factor": bandwidth_factor,
        "cutoff_hz": None if bandwidth is None else bandwidth_factor * bandwidth,
        "link_mode_frequencies_hz": link_hz,
        "modes_kept_per_link": kept,
        "start": rung_name(top if from_top else start),
        "lowest_rung_for_initial_state": rung_name(low),
        "torques_from": (
            f"the closed loop with the plant at {rung_name(top)} (the top rung: the walk starts there)"
            if from_top
            else f"the closed loop with the plant at {rung_name(first)} (the design "
            f"model's rung{', linearised' if linear is not None else ''})"
        ),
    }
    ref_dt = plant.dt / max(
        1, math.ceil(plant.dt * ref_model.omega_max / reference_omega_dt - 1e-12)
    )
    extra = {
        "kind": "closed_loop",
        "controller": str(controller or scene.controller),
        "controller_overrides": list(overrides),
        "design_fidelity": str(design),
        "comparison_grid_dt_s": plant.dt,
    }
    chosen = None
    try:
        choice = walk_and_judge(
            name=scene.name,
            tol=tol,
            low=low,
            start=start,
            top=top,
            reference=reference,
            safety=safety,
            rule=rule,
            run_rung=lambda m: rung(m),
            run_reference=lambda dt: simulate_closed_rung(
                scene, reference, dt, controller=controller, overrides=overrides, cache=cache
            ),
            reference_dt=ref_dt,
            runs=runs,
            extra={
                **extra,
                "walk": walk,
                "linear_estimate_skipped": from_top,
                "walk_taken": "from_top"
                if from_top
                else "linear_first"
                if linear is not None
                else "ladder",
            },
            linear=linear,
            factor=LINEAR_FACTOR,
            from_top=from_top,
            checks=checks,
        )
        chosen = whole_run_key(scene, str(choice.choice), choice.dt, controller, overrides)
    finally:  # only the chosen rung's whole run is worth keeping: the scene's own run at the choice
        cache.drop(WHOLE_RUNS, keep=chosen)
    choice.evidence["method"] = (
        "closed loop (controller designed once on the pinned design model) with the plant at "
        "each rung; " + choice.evidence["method"]
    )
    choice.evidence["choosing_time_s"] = time.perf_counter() - started
    return choice
