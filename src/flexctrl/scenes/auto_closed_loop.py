"""Choosing the plant's fidelity of a closed-loop scene (``fidelity = "auto"``).

The controller is designed once on the pinned design model; the plant runs at each rung
(:func:`simulate_closed_rung`) and, for the estimate-first walk, on each rung's linearized
plant (:mod:`flexctrl.scenes.auto_linear`); :func:`choose_closed_loop_fidelity` hands them to
:func:`~flexctrl.fidelity.ladder.walk_and_judge`.  Runs and choices are kept in the caller's
:class:`~flexctrl.scenes.cache.SceneCache` by :func:`closed_loop_key`.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from pathlib import Path

from flexctrl.errors import SpecError
from flexctrl.fidelity.ladder import (
    LINEAR_FACTOR,
    WALKS,
    FidelityChoice,
    RunRecord,
    check_ladder,
    check_tolerance,
    required_modes,
    rung_name,
    sampled_bandwidth,
    walk_and_judge,
)
from flexctrl.scenes.auto import check_checks, model_for
from flexctrl.scenes.auto_linear import linear_closed_rung, loop_at
from flexctrl.scenes.cache import SceneCache, read_only
from flexctrl.scenes.loop_setup import AUTO_DESIGN_FIDELITY, closed_loop_tip_path
from flexctrl.sim.rk4 import rk4_step
from flexctrl.spec.fidelity import Fidelity


def controller_digest(path: str | Path) -> str:
    """sha256 of a controller file's bytes (hex)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def closed_loop_key(
    scene, controller: str | Path | None = None, overrides: tuple[str, ...] = ()
) -> str:
    """A canonical string of everything that changes a closed loop's simulation except the plant
    fidelity.

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
    """The closed loop with the plant at ``fidelity`` and RK4 step ``dt`` (s; default method step
    4).

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


# : The cache's kind for whole closed-loop runs at a rung's own step, kept for one reuse; at most
# this many.
WHOLE_RUNS, WHOLE_RUNS_KEPT = "whole_closed_runs", 8


def whole_run_key(
    scene, fidelity: str, dt: float, controller=None, overrides: tuple[str, ...] = ()
) -> tuple:
    """The key of :data:`WHOLE_RUNS`: the chooser's scene (design pinned), the rung and its RK4 step (s)."""
    return (closed_loop_key(scene, controller, tuple(overrides)), str(fidelity), float(dt))


def check_closed_loop_auto(scene, controller=None) -> None:
    """Refuse a closed loop whose plant ``fidelity = "auto"`` cannot choose (the tolerance is
    checked apart).

    Raises
    ------
    SpecError
        Naming the scene file and key: the plant's integrator (``rk4``), the design model
        (``controller_fidelity`` not ``auto``) or a missing controller.
    """
    if scene.plant.integrator != "rk4":
        raise SpecError(
            f"value '{scene.plant.integrator}' is not allowed with fidelity = 'auto' in a closed "
            "loop; "
            "allowed: 'rk4' (the loop integrates the plant with RK4)",
            source=scene.source,
            key="integrator",
        )
    if scene.controller_fidelity is not None and scene.controller_fidelity.kind == "auto":
        raise SpecError(
            "value 'auto' is not allowed for the design model; allowed: 'rigid', 'amm:N' or "
            "'fem:N' "
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
    """The lowest plant rung of ``rigid, amm:1 .. amm:top`` estimated to keep a closed loop's tip
    within ``tol``.

    As :func:`choose_fidelity`, with every candidate a whole closed-loop run: the
    controller (the scene's or ``controller`` with ``overrides``) designed on the
    scene's ``controller_fidelity`` (pinned: the plant's fidelity is what is chosen;
    :func:`flexctrl.scenes.run_closed_loop_scene.pin_design` gives ``amm:2`` when the scene names
    none), its payload and configuration, the same for every rung; the plant at the rung, RK4 at the
    rung's step (the scene's ``dt`` divided by the smallest whole number that makes ``omega_max * dt
    <= 0.9 * 2.785``).  Differences from the arm method:

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
        ``estimate`` (default): every rung's loop first on its linearized plant
        (:mod:`flexctrl.scenes.auto_linear`, milliseconds to a second each); the lowest rung
        whose linear estimate is within :data:`~flexctrl.fidelity.ladder.LINEAR_FACTOR` of the
        tolerance is certified by the nonlinear runs of the estimate's formula, walking up
        while it fails; no rung within the factor is a predicted :class:`ToleranceUnreachable`
        without nonlinear runs; the reference is the reference model at its own step (its step
        error estimated linearly).  A controller stepped in Python (MPC, NMPC, a gain
        schedule) costs as much on a linear plant as on the nonlinear one, so for it the walk
        runs nonlinear from ``top`` down while the rung below meets the tolerance.
        ``ladder``: the nonlinear walk up from the bandwidth rule's start, the reference at
        ``reference_omega_dt`` and half its step: slower, for tolerances the linear estimates
        cannot certify.
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
            f"scene kind '{getattr(scene, 'kind', type(scene).__name__)}' is not supported here; "
            "allowed: "
            'a kind = "closed_loop" scene (choose_fidelity takes arm scenes)',
            source=getattr(scene, "source", None),
            key="kind",
        )
    if scene.controller_fidelity is None:
        raise SpecError(
            "value None is not allowed when the plant is chosen; allowed: a concrete design "
            "model, e.g. "
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
    low, first, linear, from_top, runs, record = _first_runs(
        scene, controller, overrides, cache, top, reference, walk
    )
    ref_model = model_for(plant, reference, cache)
    start, rule = _bandwidth_rule(
        record, ref_model, low, first, top, energy_fraction, bandwidth_factor
    )
    rule["start"] = rung_name(top if from_top else start)
    rule["torques_from"] = (
        f"the closed loop with the plant at {rung_name(top)} (the top rung: the walk starts there)"
        if from_top
        else f"the closed loop with the plant at {rung_name(first)} (the design "
        f"model's rung{', linearized' if linear is not None else ''})"
    )
    ref_dt = plant.dt / max(
        1, math.ceil(plant.dt * ref_model.omega_max / reference_omega_dt - 1e-12)
    )
    extra = {
        "kind": "closed_loop",
        "controller": str(controller or scene.controller),
        "controller_overrides": list(overrides),
        "design_fidelity": str(scene.controller_fidelity),
        "comparison_grid_dt_s": plant.dt,
        "walk": walk,
        "linear_estimate_skipped": from_top,
        "walk_taken": "from_top"
        if from_top
        else "linear_first"
        if linear is not None
        else "ladder",
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
            run_rung=lambda m: simulate_closed_rung(
                scene, rung_name(m), controller=controller, overrides=overrides, cache=cache
            ),
            run_reference=lambda dt: simulate_closed_rung(
                scene, reference, dt, controller=controller, overrides=overrides, cache=cache
            ),
            reference_dt=ref_dt,
            runs=runs,
            extra=extra,
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


def _first_runs(scene, controller, overrides, cache: SceneCache, top: int, reference, walk):
    """The lowest rung the initial state allows, the design model's rung, the linear runs (for
    the estimate walk), whether the walk starts at the top, and the runs made to start it."""
    low = required_modes(scene.plant)
    if low > top:
        raise SpecError(
            f"the initial elastic coordinates need {low} modes per link, above the top candidate "
            f"amm:{top}; allowed: top >= {low}",
            source=scene.source,
            key="initial.qf",
        )
    design = scene.controller_fidelity
    design_rung = (
        0 if design.kind == "rigid" else (design.count or 0) if design.kind == "amm" else top
    )
    first = min(max(low, design_rung), top)
    linear, from_top = None, False
    if walk == "estimate":
        linear = _linear_runs(scene, controller, overrides, cache, reference)
        # a controller stepped in Python costs as much on a linear plant as on the nonlinear one:
        # no linear estimate of the rungs, the nonlinear walk from the top down (the step check
        # stays linear)
        loop = loop_at(scene, rung_name(first), controller, overrides, cache)
        from_top = not loop.controller.has_sampled_law()
    if linear is not None and not from_top:  # the linear runs give the torques
        return low, first, linear, from_top, {}, linear[0](first)
    m = top if from_top else first
    record = simulate_closed_rung(
        scene, rung_name(m), controller=controller, overrides=overrides, cache=cache
    )
    return low, first, linear, from_top, {m: record}, record


def _linear_runs(scene, controller, overrides, cache: SceneCache, reference: str):
    """``(linear_rung, linear_exact)``: a rung's loop on its linearized plant at its own step,
    and the reference model's without integrator error (:func:`walk_and_judge`'s ``linear``)."""
    plant = scene.plant

    def linear_rung(m: int) -> RunRecord:
        h = rk4_step(model_for(plant, rung_name(m), cache).omega_max, plant.dt)
        return cache.get(
            "linear_runs",
            (closed_loop_key(scene, controller, overrides), rung_name(m), h),
            lambda: linear_closed_rung(
                scene, rung_name(m), h, controller=controller, overrides=overrides, cache=cache
            ),
        )

    def linear_exact() -> RunRecord:
        return linear_closed_rung(
            scene, reference, None, controller=controller, overrides=overrides, cache=cache
        )

    return linear_rung, linear_exact


def _bandwidth_rule(record, ref_model, low, first, top, energy_fraction, bandwidth_factor):
    """The walk's start from the torques' bandwidth (method step 1) and the rule's evidence."""
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
        "lowest_rung_for_initial_state": rung_name(low),
    }
    return start, rule
