"""Running closed loops for the automatic-fidelity ladder: the plant's rung chosen for a tolerance.

:func:`choose_closed_loop_fidelity` chooses the plant's rung for a ``kind = "closed_loop"``
scene as :func:`~flexctrl.scenes.auto.choose_fidelity` does for an arm scene, with every
candidate a whole closed-loop run (:func:`simulate_closed_rung`): the controller (the
scene's, or a file with overrides) designed once on the scene's pinned
``controller_fidelity`` (:func:`flexctrl.scenes.loop_setup.pin_design` gives ``amm:2`` when
the scene names none), its payload and configuration the same for every rung; the plant at
the rung, RK4 at the rung's step (the scene's ``dt`` divided by the smallest whole number
that makes ``omega_max * dt <= 0.9 * 2.785``).  Differences from the arm method:

* The excitation is the controller's torque, known only by running the loop, so the
  bandwidth rule (method step 1) reads the torques of a first run with the plant at the
  design model's rung (clipped to the ladder), with their mean removed.
* Tip paths are compared on the scene's grid (``dt``), where every rung and the reference
  have samples (their steps divide it), not at every plant step.
* A candidate whose loop diverges has an infinite distance (it cannot be chosen); a
  diverging reference raises :class:`~flexctrl.errors.SimulationError`.

The walks (``fidelity_walk``):

``estimate`` (the default)
    For a controller with a sampled law (``has_sampled_law``: its loop is one compiled
    call), every rung's loop first on its linearised plant (:mod:`flexctrl.scenes.auto_linear`);
    the lowest rung whose linear estimate is within
    :data:`~flexctrl.fidelity.ladder.LINEAR_FACTOR` of the tolerance is certified by the
    nonlinear runs of the estimate's formula, walking up while it fails; no rung within the
    factor is a predicted :class:`~flexctrl.fidelity.records.ToleranceUnreachable` without
    nonlinear runs.  For a controller stepped in Python (MPC, NMPC, a gain schedule), whose
    linear run costs what its nonlinear run does, no linear estimate of the rungs: the
    nonlinear walk from ``top`` down while the rung below meets the tolerance.  Either way
    the reference is the reference model at its own step, its step error estimated linearly.
``ladder``
    Nonlinear runs only, from the bandwidth rule's start, the reference at
    ``reference_omega_dt`` and half its step: no linear assumption (for a loop the
    linearisation at the target does not describe), at several times the cost.

Runs and choices are kept in the caller's :class:`~flexctrl.scenes.cache.SceneCache`,
keyed by everything that changes the loop (:func:`closed_loop_key`); the run at the rung
finally chosen is kept whole (:data:`WHOLE_RUNS`) for the scene's run to reuse.
"""

from __future__ import annotations

import functools
import hashlib
import json
import time
from pathlib import Path

from flexctrl.errors import SpecError
from flexctrl.fidelity.ladder import (
    FidelityChoice,
    Runners,
    RunRecord,
    check_tolerance,
    rung_name,
    sampled_bandwidth,
    walk_and_judge,
)
from flexctrl.scenes.auto import (
    ChooserOptions,
    bandwidth_rule,
    key_settings,
    link_frequencies_hz,
    lowest_rung,
    model_for,
    reference_step,
)
from flexctrl.scenes.auto_linear import linear_closed_rung, loop_at
from flexctrl.scenes.cache import SceneCache, read_only
from flexctrl.scenes.loop_setup import AUTO_DESIGN_FIDELITY, closed_loop_tip_path
from flexctrl.sim.rk4 import rk4_step
from flexctrl.spec.fidelity import Fidelity

#: The cache's kind for whole closed-loop runs at a rung's own step, kept for one reuse; at most
#: this many.
WHOLE_RUNS, WHOLE_RUNS_KEPT = "whole_closed_runs", 8


def controller_digest(path: str | Path) -> str:
    """sha256 of a controller file's bytes (hex)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def closed_loop_key(
    scene, controller: str | Path | None = None, overrides: tuple[str, ...] = ()
) -> str:
    """A canonical string of everything that changes a closed loop's run but the plant fidelity.

    The scene's settings (plant, payload, initial configuration, target, reference,
    design payload / fidelity / configuration, noise and seed, metrics windows), the
    model file's modification time, the controller file's path, sha256 and overrides.
    """
    settings = key_settings(scene, scene.plant.model, drop=("controller",))
    ctrl = controller or scene.controller
    settings["controller_file"] = None if ctrl is None else str(Path(ctrl).resolve())
    settings["controller_sha256"] = (
        None if ctrl is None or not Path(ctrl).is_file() else controller_digest(ctrl)
    )
    settings["controller_overrides"] = list(overrides)
    return json.dumps(settings, sort_keys=True, default=str)


def whole_run_key(
    scene, fidelity: str, dt: float, controller=None, overrides: tuple[str, ...] = ()
) -> tuple:
    """The key of :data:`WHOLE_RUNS`: the chooser's scene (design pinned), rung and step (s)."""
    return (closed_loop_key(scene, controller, tuple(overrides)), str(fidelity), float(dt))


def simulate_closed_rung(
    scene,
    fidelity: str,
    dt: float | None = None,
    *,
    controller: str | Path | None = None,
    overrides: tuple[str, ...] = (),
    cache: SceneCache | None = None,
) -> RunRecord:
    """The closed loop with the plant at ``fidelity``, RK4 step ``dt`` (s; default method step 4).

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
        result = closed_loop_tip_path(
            scene,
            fidelity,
            dt,
            controller=controller,
            overrides=overrides,
            stride=int(round(scene.plant.dt / dt)),
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


def check_closed_loop_auto(scene, controller=None) -> None:
    """Refuse a closed loop whose plant ``fidelity = "auto"`` cannot choose (the tolerance apart).

    Raises
    ------
    SpecError
        Naming the scene file and key: the design model (``controller_fidelity`` not
        ``auto``) or a missing controller (a closed-loop scene's integrator is always RK4:
        :func:`flexctrl.spec.closed_loop_scene.read_closed_loop_scene`).
    """
    if scene.controller_fidelity is not None and scene.controller_fidelity.kind == "auto":
        raise SpecError(
            "value 'auto' is not allowed for the design model; allowed: 'rigid', 'amm:N' or "
            f"'fem:N' (default {AUTO_DESIGN_FIDELITY!r} when the plant is auto)",
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
    """The lowest plant rung of ``rigid .. amm:top`` estimated to keep a loop's tip in ``tol``.

    Every candidate is a whole closed-loop run with the plant at the rung (module docstring).

    Parameters
    ----------
    scene : ClosedLoopScene
        Its plant's fidelity is ignored; ``controller_fidelity`` must be set (see
        :func:`flexctrl.scenes.loop_setup.pin_design`).
    tol : float
        Tolerance on the largest tip-position distance (m), > 0.
    controller : str or Path, optional
        Controller file (default: the scene's ``controller``).
    overrides : sequence of str
        ``KEY=VALUE`` overrides of the controller file.
    top, reference, safety, energy_fraction, bandwidth_factor, reference_omega_dt
        As in :func:`~flexctrl.scenes.auto.choose_fidelity`.
    cache : SceneCache, optional
        Where models, runs and the choice are kept (a fresh one when None).
    walk : {"estimate", "ladder"}
        How the rungs are walked (module docstring): ``estimate`` (default) judges by linear
        estimates first, or from the top rung down for a controller stepped in Python;
        ``ladder`` makes nonlinear runs only, with no linear assumption, at several times
        the cost.
    checks : {"full", "tolerance"}
        What is checked beyond the tolerance (:class:`~flexctrl.fidelity.walk.Ladder`).

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
    _check_scene(scene, controller)
    options = ChooserOptions.checked(
        tol,
        top=top,
        reference=reference,
        safety=safety,
        energy_fraction=energy_fraction,
        bandwidth_factor=bandwidth_factor,
        reference_omega_dt=reference_omega_dt,
        checks=checks,
        walk=walk,
        source=scene.source,
    )
    cache = SceneCache() if cache is None else cache
    overrides = tuple(overrides)
    key = (closed_loop_key(scene, controller, overrides), options)
    choose = _ClosedChoice(scene, controller, overrides, cache, options).choose
    return cache.get("closed_choices", key, choose)


def _check_scene(scene, controller) -> None:
    if getattr(scene, "kind", None) != "closed_loop":
        raise SpecError(
            f"scene kind '{getattr(scene, 'kind', type(scene).__name__)}' is not supported "
            'here; allowed: a kind = "closed_loop" scene (choose_fidelity takes arm scenes)',
            source=getattr(scene, "source", None),
            key="kind",
        )
    if scene.controller_fidelity is None:
        raise SpecError(
            "value None is not allowed when the plant is chosen; allowed: a concrete design "
            f"model, e.g. {AUTO_DESIGN_FIDELITY!r} (flexctrl.scenes.loop_setup.pin_design sets "
            "the default)",
            source=scene.source,
            key="controller_fidelity",
        )
    check_closed_loop_auto(scene, controller)


class _ClosedChoice:
    """One closed loop's choice: its runners, the walk it takes, the bandwidth rule, the walk."""

    def __init__(self, scene, controller, overrides, cache: SceneCache, options: ChooserOptions):
        self.scene, self.controller, self.overrides = scene, controller, overrides
        self.cache, self.options = cache, options

    @functools.cached_property
    def key(self) -> str:
        """:func:`closed_loop_key` of the loop, for the linear runs kept in the cache."""
        return closed_loop_key(self.scene, self.controller, self.overrides)

    def rung(self, m: int) -> RunRecord:
        """Rung ``m``'s nonlinear run at its own step."""
        return simulate_closed_rung(
            self.scene,
            rung_name(m),
            controller=self.controller,
            overrides=self.overrides,
            cache=self.cache,
        )

    def reference(self, dt: float) -> RunRecord:
        """The reference model's run at step ``dt`` (s): the ladder walk's reference."""
        return simulate_closed_rung(
            self.scene,
            self.options.reference,
            dt,
            controller=self.controller,
            overrides=self.overrides,
            cache=self.cache,
        )

    def linear_rung(self, m: int) -> RunRecord:
        """Rung ``m``'s loop on its linearised plant at the rung's own step, kept in the cache."""
        plant, name = self.scene.plant, rung_name(m)
        h = rk4_step(model_for(plant, name, self.cache).omega_max, plant.dt)
        return self.cache.get(
            "linear_runs",
            (self.key, name, h),
            lambda: linear_closed_rung(
                self.scene,
                name,
                h,
                controller=self.controller,
                overrides=self.overrides,
                cache=self.cache,
            ),
        )

    def linear_exact(self) -> RunRecord:
        """The reference model's linear loop without integrator error."""
        return linear_closed_rung(
            self.scene,
            self.options.reference,
            None,
            controller=self.controller,
            overrides=self.overrides,
            cache=self.cache,
        )

    def walk_kind(self, first: int) -> str:
        """``ladder`` when asked; else ``linear_first``, or ``from_top`` without a sampled law.

        A controller without a sampled law is stepped in Python: its linear run costs what its
        nonlinear run does, so its rungs are not estimated linearly.
        """
        if self.options.walk == "ladder":
            return "ladder"
        setup = loop_at(self.scene, rung_name(first), self.controller, self.overrides, self.cache)
        return "linear_first" if setup.controller.has_sampled_law() else "from_top"

    def choose(self) -> FidelityChoice:
        """The walk from the bandwidth rule, the choice, and its whole run kept for the scene."""
        started = time.perf_counter()
        scene, options, top = self.scene, self.options, self.options.top
        low = lowest_rung(scene.plant, top, scene.source)
        first = min(max(low, _design_rung(scene.controller_fidelity, top)), top)
        walk = self.walk_kind(first)
        runs, record = self.first_run(walk, first)
        ref_model = model_for(scene.plant, options.reference, self.cache)
        start, rule = self.bandwidth_rule(record, ref_model, low, first, walk)
        chosen = None
        try:
            choice = walk_and_judge(
                options.ladder(scene.name, low),
                Runners(
                    rung=self.rung,
                    reference=self.reference,
                    reference_dt=reference_step(
                        scene.plant.dt, ref_model.omega_max, options.reference_omega_dt
                    ),
                    linear_rung=None if walk == "ladder" else self.linear_rung,
                    linear_exact=None if walk == "ladder" else self.linear_exact,
                ),
                walk=walk,
                start=start,
                rule=rule,
                runs=runs,
                extra=self.evidence(walk),
            )
            chosen = whole_run_key(
                scene, str(choice.choice), choice.dt, self.controller, self.overrides
            )
        finally:  # only the chosen rung's whole run is worth keeping: the scene's own run at it
            self.cache.drop(WHOLE_RUNS, keep=chosen)
        choice.evidence["method"] = (
            "closed loop (controller designed once on the pinned design model) with the plant at "
            "each rung; " + choice.evidence["method"]
        )
        choice.evidence["choosing_time_s"] = time.perf_counter() - started
        return choice

    def first_run(self, walk: str, first: int) -> tuple[dict[int, RunRecord], RunRecord]:
        """The run whose torques give the bandwidth, and the nonlinear runs made so far.

        From the top: the top rung's run.  The linear-first walk: the design rung's linear
        run, so no nonlinear run is made before the candidate is known.  The ladder walk:
        the design rung's run.
        """
        if walk == "from_top":
            runs = {self.options.top: self.rung(self.options.top)}
            return runs, runs[self.options.top]
        if walk == "linear_first":
            return {}, self.linear_rung(first)
        runs = {first: self.rung(first)}
        return runs, runs[first]

    def bandwidth_rule(self, record: RunRecord, ref_model, low: int, first: int, walk: str):
        """Method step 1 on the first run's torques: the start and the rule's evidence."""
        options, top = self.options, self.options.top
        bandwidth = None
        if record.torque is not None and record.diverged_at is None and record.time.size > 2:
            bandwidth = sampled_bandwidth(
                record.torque,
                float(record.time[1] - record.time[0]),
                energy_fraction=options.energy_fraction,
            )
        start, rule = bandwidth_rule(
            bandwidth, link_frequencies_hz(ref_model), options, low=low, fallback=first
        )
        from_top = walk == "from_top"
        rule["start"] = rung_name(top if from_top else start)
        rule["torques_from"] = (
            f"the closed loop with the plant at {rung_name(top)} (the top rung: the walk starts "
            "there)"
            if from_top
            else f"the closed loop with the plant at {rung_name(first)} (the design "
            f"model's rung{', linearised' if walk == 'linear_first' else ''})"
        )
        return start, rule

    def evidence(self, walk: str) -> dict:
        """What the choice's evidence adds to the walk's: the loop, and the walk taken."""
        scene = self.scene
        return {
            "kind": "closed_loop",
            "controller": str(self.controller or scene.controller),
            "controller_overrides": list(self.overrides),
            "design_fidelity": str(scene.controller_fidelity),
            "comparison_grid_dt_s": scene.plant.dt,
            "walk": self.options.walk,
            "linear_estimate_skipped": walk == "from_top",
            "walk_taken": walk,
        }


def _design_rung(design: Fidelity, top: int) -> int:
    """The rung of the design model: its modes per link (rigid 0), ``top`` for finite elements."""
    if design.kind == "rigid":
        return 0
    return (design.count or 0) if design.kind == "amm" else top
