"""Running arm scenes for the automatic-fidelity ladder (:mod:`flexctrl.fidelity.ladder`).

The ladder's method is pure: it judges runs it is handed.  This module makes those runs
for a ``kind = "arm"`` scene (:func:`simulate_rung`) and connects them to
:func:`~flexctrl.fidelity.ladder.walk_and_judge` (:func:`choose_fidelity`); it also holds
what both choosers share: their options (:class:`ChooserOptions`), the bandwidth rule's
evidence and the reference's step.  Closed loops are
:mod:`flexctrl.scenes.auto_closed_loop`'s.

Models, set-up integrators, runs and whole choices are kept in the
:class:`~flexctrl.scenes.cache.SceneCache` the caller passes (``cache=``), keyed by
everything that changes them (:func:`scene_key`), so a study running one scene many times
on one cache chooses once.  Without a cache, a fresh one serves the call.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flexctrl.errors import SpecError
from flexctrl.fidelity.ladder import (
    IMPLICIT,
    FidelityChoice,
    Ladder,
    Runners,
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
from flexctrl.spec.fidelity import FIDELITY_CHECKS, FIDELITY_WALKS, Fidelity, parse_fidelity

#: Scene settings that do not change a run at a given fidelity (left out of the keys).
_NOT_IN_KEY = (
    "fidelity",
    "tolerance_m",
    "fidelity_walk",
    "fidelity_checks",
    "name",
    "source",
    "fft_span",
    "fft_peaks",
)


@dataclass(frozen=True)
class ChooserOptions:
    """The options of a fidelity choice, validated: part of the key a choice is kept under.

    Attributes
    ----------
    tol : float
        Tolerance on the largest tip distance (m).
    top : int
        Highest candidate rung (``amm:top``), 1..5.
    reference : str
        The reference model, ``amm:R`` with ``top < R <= 6``.
    safety : float
        Factor (>= 1) on the distance to the next rungs that makes the error estimate.
    energy_fraction : float
        Share of the torque energy that defines the excitation bandwidth, in (0, 1).
    bandwidth_factor : float
        Modes below this times the bandwidth are kept by the starting rung (> 0).
    reference_omega_dt : float
        ``omega_max * dt`` of the ladder walk's reference step (0 < value <= 2.5).
    checks : {"full", "tolerance"}
        What is checked beyond the tolerance (:class:`~flexctrl.fidelity.walk.Ladder`).
    walk : {"estimate", "ladder"}
        How a closed loop's rungs are walked; arm scenes always take the ladder walk.
    """

    tol: float
    top: int = 4
    reference: str = "amm:5"
    safety: float = 2.0
    energy_fraction: float = 0.99
    bandwidth_factor: float = 5.0
    reference_omega_dt: float = 0.5
    checks: str = "full"
    walk: str = "ladder"

    @classmethod
    def checked(
        cls,
        tol,
        *,
        top,
        reference,
        safety,
        energy_fraction,
        bandwidth_factor,
        reference_omega_dt,
        checks,
        walk="ladder",
        source: str | None = None,
    ) -> ChooserOptions:
        """The options validated; :class:`SpecError` names a bad one and what is allowed."""
        tol = check_tolerance(tol, key="tolerance")
        ref = check_ladder(
            top, reference, safety, energy_fraction, bandwidth_factor, reference_omega_dt
        )
        for key, value, allowed in (
            ("fidelity_checks", checks, FIDELITY_CHECKS),
            ("fidelity_walk", walk, FIDELITY_WALKS),
        ):
            if value not in allowed:
                raise SpecError(
                    f"value {value!r} is not allowed; allowed: {', '.join(map(repr, allowed))}",
                    source=source,
                    key=key,
                )
        return cls(
            tol,
            top,
            str(ref),
            float(safety),
            float(energy_fraction),
            float(bandwidth_factor),
            float(reference_omega_dt),
            checks,
            walk,
        )

    def ladder(self, name: str, low: int) -> Ladder:
        """The question the walk answers for scene ``name`` from rung ``low``."""
        return Ladder(name, self.tol, low, self.top, self.reference, self.safety, self.checks)


def scene_key(scene) -> str:
    """A canonical string of everything in an arm scene that changes its simulation.

    Everything but its fidelity, the chooser's settings and the outputs, with the model
    file's modification time.
    """
    return json.dumps(key_settings(scene, scene.model), sort_keys=True, default=str)


def key_settings(scene, model: str | Path, drop: tuple[str, ...] = ()) -> dict[str, Any]:
    """The scene's settings that change a run at a given fidelity (for :func:`scene_key`).

    ``model`` is its model file, whose modification time is added; ``drop`` more settings
    to leave out.
    """
    settings = scene.settings()
    for name in (*_NOT_IN_KEY, *drop):
        settings.pop(name, None)
    path = Path(model)
    settings["model_mtime_ns"] = path.stat().st_mtime_ns if path.is_file() else None
    return settings


def model_for(scene, fidelity: str, cache: SceneCache):
    """The arm scene's model at ``fidelity``, from ``cache``."""
    return cache.model(scene_arm(scene), fidelity, scene.modes, scene.q0)


def lowest_rung(scene, top: int, source: str) -> int:
    """The lowest rung that holds the scene's initial elastic coordinates, at most ``top``."""
    low = required_modes(scene)
    if low > top:
        raise SpecError(
            f"the initial elastic coordinates need {low} modes per link, above the top candidate "
            f"amm:{top}; allowed: top >= {low}",
            source=source,
            key="initial.qf",
        )
    return low


def link_frequencies_hz(model) -> list[list[float]]:
    """Per link, its modes' clamped-mass frequencies (Hz) on ``model``."""
    return [
        [w / (2 * math.pi) for w in link] for link in model.info.get("link_frequencies_rad_s", [])
    ]


def bandwidth_rule(
    bandwidth: float | None,
    link_hz: list[list[float]],
    options: ChooserOptions,
    *,
    low: int,
    fallback: int,
) -> tuple[int, dict[str, Any]]:
    """Method step 1: the starting rung from the excitation bandwidth (Hz), and its evidence.

    Without a bandwidth (no torque), the start is ``fallback``.
    """
    if bandwidth is None:
        start, kept = fallback, None
    else:
        limit = options.bandwidth_factor * bandwidth
        kept = [sum(1 for f in link if f <= limit) for link in link_hz]
        start = min(max([low, *kept]), options.top)
    return start, {
        "excitation_bandwidth_hz": bandwidth,
        "energy_fraction": options.energy_fraction,
        "factor": options.bandwidth_factor,
        "cutoff_hz": None if bandwidth is None else options.bandwidth_factor * bandwidth,
        "link_mode_frequencies_hz": link_hz,
        "modes_kept_per_link": kept,
        "start": rung_name(start),
        "lowest_rung_for_initial_state": rung_name(low),
    }


def reference_step(dt: float, omega_max: float, reference_omega_dt: float) -> float:
    """The ladder walk's reference step (s): ``dt`` divided until ``omega_max * step`` is small."""
    return dt / max(1, math.ceil(dt * omega_max / reference_omega_dt - 1e-12))


def _run_settings(scene, model) -> tuple[str, float]:
    """Integrator and step for a rung (method step 4 of :mod:`flexctrl.fidelity.ladder`)."""
    if scene.integrator in IMPLICIT:
        return scene.integrator, scene.dt
    return "rk4", rk4_step(model.omega_max, scene.dt)


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
    """The cached model and set-up integrator of a scene at a concrete fidelity, integrator, step.

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
    """The lowest rung of ``rigid, amm:1 .. amm:top`` estimated to keep the tip within ``tol``.

    The method is :mod:`flexctrl.fidelity.ladder`'s, with the ladder walk.

    Parameters
    ----------
    scene : ArmScene
        A ``kind = "arm"`` scene (its fidelity is ignored); a closed-loop scene's ``plant``
        is not accepted.
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
        What is checked beyond the tolerance (:class:`~flexctrl.fidelity.walk.Ladder`).

    Returns
    -------
    FidelityChoice
        The rung, its integrator and step, its estimate and distance from the reference.

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
    options = ChooserOptions.checked(
        tol,
        top=top,
        reference=reference,
        safety=safety,
        energy_fraction=energy_fraction,
        bandwidth_factor=bandwidth_factor,
        reference_omega_dt=reference_omega_dt,
        checks=checks,
        source=scene.source,
    )
    cache = SceneCache() if cache is None else cache
    return cache.get("choices", (scene_key(scene), options), lambda: _choose(scene, cache, options))


def _choose(scene, cache: SceneCache, options: ChooserOptions) -> FidelityChoice:
    low = lowest_rung(scene, options.top, scene.source)
    # (a) the modal-bandwidth rule, on the finest model's per-link mode frequencies
    top_model = model_for(scene, options.reference, cache)
    bandwidth = excitation_bandwidth(
        scene, top_model.n_joints, energy_fraction=options.energy_fraction
    )
    start, rule = bandwidth_rule(
        bandwidth, link_frequencies_hz(top_model), options, low=low, fallback=low
    )
    reference = options.reference
    return walk_and_judge(
        options.ladder(scene.name, low),
        Runners(
            rung=lambda m: simulate_rung(scene, rung_name(m), cache=cache),
            reference=lambda dt: simulate_rung(scene, reference, "rk4", dt, cache=cache),
            reference_dt=reference_step(scene.dt, top_model.omega_max, options.reference_omega_dt),
        ),
        walk="ladder",
        start=start,
        rule=rule,
    )
