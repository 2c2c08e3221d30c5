"""Running scenes for the automatic-fidelity ladder (:mod:`flexctrl.fidelity.ladder`).

The ladder's method is pure: it judges runs it is handed.  This module makes those
runs: an arm scene at a rung (:func:`simulate_rung`), a closed loop with the plant at
a rung (:mod:`flexctrl.scenes.auto_closed_loop`), and the choosers that connect them to
:func:`~flexctrl.fidelity.ladder.walk_and_judge`: :func:`choose_fidelity` (``kind =
"arm"``) here and :func:`~flexctrl.scenes.auto_closed_loop.choose_closed_loop_fidelity`
(``kind = "closed_loop"``).

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
    FidelityChoice,
    RunRecord,
    check_ladder,
    check_tolerance,
    excitation_bandwidth,
    required_modes,
    rung_name,
    walk_and_judge,
)
from flexctrl.scenes.arm_setup import scene_arm, simulate_arm_scene
from flexctrl.scenes.cache import SceneCache, read_only
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
    """The cached model and set-up integrator for a scene at a concrete fidelity, integrator and
    step.

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
    """The lowest rung of ``rigid, amm:1 .. amm:top`` estimated to keep the tip within ``tol`` (see
    module docstring).

    Parameters
    ----------
    scene : ArmScene
        A ``kind = "arm"`` scene (its fidelity is ignored); a closed-loop scene's ``plant`` is not
        accepted.
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
            f"scene kind '{getattr(scene, 'kind', type(scene).__name__)}' is not supported; "
            'allowed: a kind = "arm" scene',
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
    low = required_modes(scene)
    if low > top:
        raise SpecError(
            f"the initial elastic coordinates need {low} modes per link, above the top candidate "
            f"amm:{top}; "
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
