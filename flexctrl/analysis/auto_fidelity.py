"""The cheapest model that meets a scene's tip-accuracy tolerance (issue 7, ``fidelity = "auto"``).

:func:`choose_fidelity` picks, for one ``kind = "arm"`` scene and a tolerance on
the tip position (m), the lowest rung of the ladder ``rigid -> amm:1 -> amm:2 ->
...`` whose tip path is estimated to stay within the tolerance, and measures that
claim against a converged reference.  The method:

1. **Modal-bandwidth rule (starting rung).**  The excitation bandwidth ``B`` is
   the frequency below which ``energy_fraction`` (default 99 %) of the energy of
   the scene's joint torques lies (their spectrum over the scene's duration,
   :func:`excitation_bandwidth`).  Mode ``k`` of link ``i`` (its clamped-mass
   frequency with the rest of the arm as boundary, ``Model.info
   ["link_frequencies_rad_s"]``) is kept when it lies below
   ``bandwidth_factor * B`` (default 5); the starting rung keeps, on every link,
   as many modes as the most demanding link needs.  Without a torque (free
   vibration) the rule gives no bound and the walk starts at the lowest rung
   that holds the scene's initial elastic coordinates (``qf32`` needs ``amm:2``).
2. **Error estimate by the rungs above ("Richardson-like").**  The estimate of
   rung ``N`` is ``safety`` (default 2) times the largest tip distance between
   rung ``N`` and rungs ``N + 1`` and ``N + 2`` (up to the reference model), each
   run with the integrator and step it would be run with.  The factor 2 covers
   geometric convergence whose successive differences shrink at least by half
   (error <= d / (1 - r) <= 2 d for r <= 1/2); the measured ratio of successive
   differences is recorded so a reader can check that assumption.  Two rungs, not
   one, because convergence in modes per link is not monotone: on a slow move the
   first mode per link changes the tip less than the second does, and ``rigid``
   against ``amm:1`` alone underestimated the error by a factor of 2.4.  From the
   starting rung the walk goes *up* while the estimate exceeds the tolerance, or
   *down* while the rung below also meets it; the choice is the lowest rung
   reached whose estimate meets the tolerance.
3. **Reference.**  ``amm:R`` (default ``amm:5``, one rung above the top
   candidate) with RK4 at ``omega_max * dt <= reference_omega_dt`` (default 0.5).
   Its convergence is shown by two refinements: the same model at half the step
   (time) and the rung below at its own step (model); both distances are
   recorded, and a :class:`UserWarning` is issued when either exceeds half the
   tolerance (the reference would then not be fit to judge the choice).  The
   chosen rung's tip distance from the reference is ``reference_error``.
4. **Integrator and step.**  A scene with an implicit integrator (``cvodes``,
   ``idas``, ``scipy``) keeps it and its step.  With ``rk4``, a rung keeps the
   scene's step when ``omega_max * dt <= 0.9 * 2.785`` (RK4's stability limit
   with a 10 % margin); otherwise the step is the scene's divided by the
   smallest whole number that satisfies it, so outputs and torque switching
   still fall on the scene's grid.

Every simulation's wall time (``time.perf_counter``, integration only; model
build and compilation recorded apart) is kept; ``cost_ratio`` is the choice's
integration wall time over the reference's.

Models are built once per process (:func:`cached_model`, an ``lru_cache`` keyed
by the arm, the fidelity and the build options); tip paths of runs are cached by
scene, rung, integrator and step, and whole choices by scene, tolerance and
options, so a study running one scene many times chooses once.

Examples
--------
>>> from flexctrl.spec.scene import load_scene
>>> from flexctrl.analysis.auto_fidelity import choose_fidelity
>>> scene = load_scene("studies/scenes/slow_move_light.toml", ["duration=1.0"])
>>> choice = choose_fidelity(scene, 1e-3, top=2, reference="amm:3")  # doctest: +SKIP
>>> str(choice.choice)  # doctest: +SKIP
'rigid'
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import re
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.analysis.tip_error import TipError, tip_error
from flexctrl.errors import FlexctrlError, SimulationError, SpecError
from flexctrl.fidelity import Fidelity, parse_fidelity

#: RK4's stability limit on ``omega * dt`` (as :class:`flexctrl.sim.rk4.RK4`) and the margin used.
RK4_LIMIT = 2.785
RK4_MARGIN = 0.9
IMPLICIT = ("cvodes", "idas", "scipy")
_QF = re.compile(r"^qf(\d+?)(\d)$")


class ToleranceUnreachable(FlexctrlError):
    """No rung of the ladder meets the tolerance; ``evidence`` holds what was measured."""

    def __init__(self, message: str, evidence: dict[str, Any]):
        super().__init__(message)
        self.evidence = evidence


@dataclass(frozen=True)
class RunRecord:
    """One simulation made while choosing.

    Attributes
    ----------
    fidelity : str
    integrator : str
    dt : float
        Step (s).
    omega_max : float
        The model's ``omega_max`` (rad/s).
    wall_time_s : float
        Integration wall time (s).
    build_time_s : float
        Model build plus integrator setup (compilation or cache load) in this process (s).
    time, tip : numpy.ndarray
        Sample times (s) and tip positions (m).
    diverged_at : float or None
        Time (s) a closed loop diverged (its tip path stops there), None when it did not.
    torque : numpy.ndarray or None
        Joint torques (N m) on ``time`` (closed-loop runs: the controller's), else None.
    """

    fidelity: str
    integrator: str
    dt: float
    omega_max: float
    wall_time_s: float
    build_time_s: float
    time: np.ndarray = field(repr=False)
    tip: np.ndarray = field(repr=False)
    diverged_at: float | None = None
    torque: np.ndarray | None = field(default=None, repr=False)

    def facts(self) -> dict[str, Any]:
        """JSON-ready settings and timings."""
        facts = {"fidelity": self.fidelity, "integrator": self.integrator, "dt_s": self.dt,
                 "omega_max_rad_s": self.omega_max, "omega_max_dt": self.omega_max * self.dt,
                 "wall_time_s": self.wall_time_s, "build_time_s": self.build_time_s}
        if self.diverged_at is not None:
            facts["diverged_at_s"] = self.diverged_at
        return facts


@dataclass(frozen=True)
class FidelityChoice:
    """The outcome of :func:`choose_fidelity`.

    Attributes
    ----------
    choice : Fidelity
        The chosen rung (a ``--fidelity`` spelling through ``str``).
    tolerance : float
        Tolerance on the tip position (m).
    estimated_error : float
        ``safety`` times the largest tip distance to the next rung (m): the estimate that justified the choice.
    reference_error : float
        Largest tip distance of the choice from the reference (m).
    reference_error_rms : float
        Its root mean square (m).
    cost_ratio : float
        Integration wall time of the choice over that of the reference.
    integrator : str
    dt : float
        Integrator and step (s) the choice is run with.
    evidence : dict
        Everything measured: the bandwidth rule, every rung's run and estimate, the
        reference and its convergence checks (see :meth:`to_dict`).
    """

    choice: Fidelity
    tolerance: float
    estimated_error: float
    reference_error: float
    reference_error_rms: float
    cost_ratio: float
    integrator: str
    dt: float
    evidence: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the four headline keys first, then the evidence."""
        return {
            "choice": str(self.choice), "tolerance_m": self.tolerance, "estimated_error": self.estimated_error,
            "reference_error": self.reference_error, "reference_error_rms": self.reference_error_rms,
            "cost_ratio": self.cost_ratio, "integrator": self.integrator, "dt_s": self.dt, **self.evidence,
        }


# -- caches ---------------------------------------------------------------------------------
@functools.lru_cache(maxsize=32)
def cached_model(arm, fidelity: str, modes: str = "frozen", reference_q: tuple[float, ...] | None = None):
    """:func:`flexctrl.dynamics.build.build_model`, built once per process per argument set.

    Parameters
    ----------
    arm : flexctrl.spec.arm.ArmSpec
        A frozen (hashable) arm description.
    fidelity : str
        ``"rigid"``, ``"amm:N"`` or ``"fem:N"``.
    modes, reference_q
        As in :func:`~flexctrl.dynamics.build.build_model` (angles in rad).
    """
    from flexctrl.dynamics.build import build_model

    return build_model(arm, fidelity, modes=modes, reference_q=reference_q)


@functools.lru_cache(maxsize=32)
def _cached_integrator(arm, fidelity: str, modes: str, reference_q, integrator: str, dt: float,
                       solver: tuple[tuple[str, Any], ...]):
    """A set-up integrator for :func:`cached_model` (arguments hashable) and its setup time (s)."""
    from flexctrl.sim import get_integrator

    start = time.perf_counter()
    model = cached_model(arm, fidelity, modes, reference_q)
    built = get_integrator(integrator)(model, dt, **dict(solver)).setup()
    return built, time.perf_counter() - start


def scene_key(scene) -> str:
    """A canonical string of everything in an arm scene that changes its simulation (not its fidelity)."""
    settings = scene.settings()
    for name in ("fidelity", "tolerance_m", "name", "source", "fft_span", "fft_peaks"):
        settings.pop(name, None)
    path = Path(scene.model)
    settings["model_mtime_ns"] = path.stat().st_mtime_ns if path.is_file() else None
    return json.dumps(settings, sort_keys=True, default=str)


class _Keyed:
    """A scene carried through ``lru_cache`` by its :func:`scene_key`."""

    def __init__(self, scene):
        self.scene = scene
        self.key = scene_key(scene)

    def __hash__(self) -> int:
        return hash(self.key)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Keyed) and other.key == self.key


def clear_caches() -> None:
    """Forget every cached model, integrator, run and choice of this process."""
    for fn in (cached_model, _cached_integrator, _run_cached, _choose_cached, _closed_run_cached, _choose_closed_cached):
        fn.cache_clear()


# -- the pieces of the method -----------------------------------------------------------------
def excitation_bandwidth(scene, n_joints: int, *, energy_fraction: float = 0.99) -> float | None:
    """Frequency (Hz) below which ``energy_fraction`` of the scene's torque energy lies.

    The torques of ``scene.input`` are sampled at the scene's step (refined to at
    most 0.1 ms) over the scene's duration, zero-padded to four times that length,
    and their energy spectrum summed over joints.

    Parameters
    ----------
    scene : ArmScene
    n_joints : int
    energy_fraction : float
        In (0, 1).

    Returns
    -------
    float or None
        The bandwidth (Hz), or None when the scene applies no torque.
    """
    k = max(1, math.ceil(scene.dt / 1e-4 - 1e-9))
    h = scene.dt / k
    n = max(2, int(math.ceil(scene.duration / h - 1e-9)))
    torque = scene.input.torque((np.arange(n) + 0.5) * h, n_joints)
    if not np.any(torque):
        return None
    n_fft = 1 << int(math.ceil(math.log2(4 * n)))
    spectrum = np.sum(np.abs(np.fft.rfft(torque, n=n_fft, axis=0)) ** 2, axis=1)
    spectrum[1:] *= 2.0  # one-sided
    cumulative = np.cumsum(spectrum) / spectrum.sum()
    freqs = np.fft.rfftfreq(n_fft, h)
    return float(freqs[min(int(np.searchsorted(cumulative, energy_fraction)), freqs.size - 1)])


def required_modes(scene) -> int:
    """Fewest modes per link that hold the scene's initial elastic coordinates (``qf<link><mode>``)."""
    need = 0
    for name in scene.qf0:
        match = _QF.match(name)
        if match:
            need = max(need, int(match.group(2)))
    return need


def rk4_step(omega_max: float, scene_dt: float, margin: float = RK4_MARGIN) -> float:
    """The scene's step divided by the smallest whole number that makes RK4 stable (s).

    ``omega_max * dt <= margin * 2.785``; the scene's step itself when it already is.
    """
    if omega_max <= 0:
        return scene_dt
    k = max(1, math.ceil(scene_dt * omega_max / (margin * RK4_LIMIT) - 1e-12))
    return scene_dt / k


def _rung(n: int) -> str:
    return "rigid" if n == 0 else f"amm:{n}"


def _run_settings(scene, model) -> tuple[str, float]:
    """Integrator and step for a rung (method step 4)."""
    if scene.integrator in IMPLICIT:
        return scene.integrator, scene.dt
    return "rk4", rk4_step(model.omega_max, scene.dt)


def simulate_rung(scene, fidelity: str, integrator: str | None = None, dt: float | None = None) -> RunRecord:
    """Simulate ``scene`` at ``fidelity`` (cached per process); the integrator and step default to method step 4.

    Raises
    ------
    SimulationError
        If the run diverges.
    """
    model = _model_for(scene, fidelity)
    if integrator is None or dt is None:
        integrator, dt = _run_settings(scene, model)
    return _run_cached(_Keyed(scene), fidelity, integrator, float(dt))


def _model_for(scene, fidelity: str):
    from flexctrl.scenes import scene_arm

    return cached_model(scene_arm(scene), fidelity, scene.modes, scene.q0)


@functools.lru_cache(maxsize=64)
def _run_cached(keyed: _Keyed, fidelity: str, integrator: str, dt: float) -> RunRecord:
    from flexctrl.scenes import simulate_arm_scene

    scene = keyed.scene
    start = time.perf_counter()
    model = _model_for(scene, fidelity)
    solver = {k: v for k, v in scene.solver.items() if integrator == scene.integrator}
    from flexctrl.scenes import scene_arm

    built, _setup = _cached_integrator(scene_arm(scene), fidelity, scene.modes, scene.q0, integrator, dt,
                                       tuple(sorted(solver.items())))
    build = time.perf_counter() - start
    run_scene = dataclasses.replace(scene, fidelity=parse_fidelity(fidelity), integrator=integrator, dt=dt)
    trajectory, model, _arm = simulate_arm_scene(run_scene, model=model, integrator=built)
    return RunRecord(fidelity=fidelity, integrator=integrator, dt=dt, omega_max=float(model.omega_max),
                     wall_time_s=float(trajectory.meta["wall_time_s"]), build_time_s=build,
                     time=trajectory.time.copy(), tip=trajectory.tip.copy())


def prepared(scene) -> tuple[Any, Any]:
    """The cached model and set-up integrator for a scene at a concrete fidelity, integrator and step.

    Used to run a scene that ``fidelity = "auto"`` resolved: the chooser has built both already.
    """
    from flexctrl.scenes import scene_arm

    fidelity = str(scene.fidelity)
    solver = tuple(sorted(scene.solver.items()))
    integrator, _setup = _cached_integrator(scene_arm(scene), fidelity, scene.modes, scene.q0, scene.integrator,
                                            float(scene.dt), solver)
    return integrator.model, integrator


def _distance(a: RunRecord, b: RunRecord):
    """Tip distance of ``b`` from ``a`` on ``a``'s samples (the finer run goes first); infinite if either diverged."""
    if a.diverged_at is not None or b.diverged_at is not None:
        return TipError(rms=math.inf, max=math.inf)
    first, second = (a, b) if a.dt <= b.dt else (b, a)
    return tip_error(first.time, first.tip, second.time, second.tip)


# -- the method -------------------------------------------------------------------------------
def _check_ladder(top, reference, safety, energy_fraction, bandwidth_factor, reference_omega_dt):
    """Validate the chooser's options (shared by the arm and closed-loop choosers); returns the reference fidelity."""
    if isinstance(top, bool) or not isinstance(top, int) or not 1 <= top <= 5:
        raise SpecError(f"value {top!r} is not allowed; allowed: an integer 1..5 (amm:top is the highest candidate)", key="top")
    ref = parse_fidelity(reference if reference is not None else f"amm:{top + 1}", key="reference")
    if ref.kind != "amm" or not top < (ref.count or 0) <= 6:
        raise SpecError(f"value '{ref}' is not allowed; allowed: 'amm:R' with {top} < R <= 6 (above the top candidate amm:{top})",
                        key="reference")
    for name, value, low, high in (("safety", safety, 1.0, 100.0), ("energy_fraction", energy_fraction, 0.0, 1.0),
                                   ("bandwidth_factor", bandwidth_factor, 0.0, 1e3),
                                   ("reference_omega_dt", reference_omega_dt, 0.0, 2.5)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high or value == 0:
            raise SpecError(f"value {value!r} is not allowed; allowed: a number in ({low:g}, {high:g}]", key=name)
    return ref


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
        raise SpecError(f"scene kind '{getattr(scene, 'kind', type(scene).__name__)}' is not supported; allowed: a kind = \"arm\" scene",
                        source=getattr(scene, "source", None), key="kind")
    ref = _check_ladder(top, reference, safety, energy_fraction, bandwidth_factor, reference_omega_dt)
    keyed = _Keyed(scene)
    return _choose_cached(keyed, tol, top, str(ref), float(safety), float(energy_fraction), float(bandwidth_factor),
                          float(reference_omega_dt))


def check_tolerance(tol: Any, *, source: str | None = None, key: str = "tolerance") -> float:
    """``tol`` as a float if it is a finite number > 0 (m), else :class:`SpecError`."""
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not math.isfinite(tol) or tol <= 0:
        raise SpecError(f"value {tol!r} is not allowed; allowed: a finite number > 0 (m, tip-position tolerance)",
                        source=source, key=key)
    return float(tol)


@functools.lru_cache(maxsize=16)
def _choose_cached(keyed: _Keyed, tol: float, top: int, reference: str, safety: float, energy_fraction: float,
                   bandwidth_factor: float, reference_omega_dt: float) -> FidelityChoice:
    scene = keyed.scene
    ref_n = parse_fidelity(reference).count
    low = required_modes(scene)
    if low > top:
        raise SpecError(f"the initial elastic coordinates need {low} modes per link, above the top candidate amm:{top}; "
                        f"allowed: top >= {low}", source=scene.source, key="initial.qf")

    # (a) the modal-bandwidth rule, on the finest model's per-link mode frequencies
    top_model = _model_for(scene, reference)
    n_joints = top_model.n_joints
    bandwidth = excitation_bandwidth(scene, n_joints, energy_fraction=energy_fraction)
    link_hz = [[w / (2 * math.pi) for w in link] for link in top_model.info.get("link_frequencies_rad_s", [])]
    if bandwidth is None:
        start = low
        kept = None
    else:
        limit = bandwidth_factor * bandwidth
        kept = [sum(1 for f in link if f <= limit) for link in link_hz]
        start = min(max([low, *kept]), top)
    rule = {"excitation_bandwidth_hz": bandwidth, "energy_fraction": energy_fraction, "factor": bandwidth_factor,
            "cutoff_hz": None if bandwidth is None else bandwidth_factor * bandwidth,
            "link_mode_frequencies_hz": link_hz, "modes_kept_per_link": kept, "start": _rung(start),
            "lowest_rung_for_initial_state": _rung(low)}

    ref_model = _model_for(scene, reference)
    ref_dt = scene.dt / max(1, math.ceil(scene.dt * ref_model.omega_max / reference_omega_dt - 1e-12))
    return _walk_and_judge(
        name=scene.name, tol=tol, low=low, start=start, top=top, reference=reference, safety=safety, rule=rule,
        run_rung=lambda m: simulate_rung(scene, _rung(m)),
        run_reference=lambda dt: simulate_rung(scene, reference, "rk4", dt), reference_dt=ref_dt)


def _walk_and_judge(*, name: str, tol: float, low: int, start: int, top: int, reference: str, safety: float,
                    rule: dict[str, Any], run_rung, run_reference, reference_dt: float,
                    runs: dict[int, RunRecord] | None = None, extra: dict[str, Any] | None = None) -> FidelityChoice:
    """Method steps 2 and 3, shared by arm and closed-loop scenes.

    Parameters
    ----------
    run_rung : callable
        ``run_rung(m) -> RunRecord``: rung ``m`` (0 = rigid) with its own integrator and step.
    run_reference : callable
        ``run_reference(dt) -> RunRecord``: the reference model with RK4 at step ``dt`` (s).
    reference_dt : float
        The reference's step (s).
    runs : dict, optional
        Rungs already run (by rung number).
    extra : dict, optional
        Added to the evidence.
    """
    ref_n = parse_fidelity(reference).count
    # (b) the walk, estimates from the (two) rungs above
    distances: dict[int, Any] = {}
    runs = dict(runs or {})

    def run(m: int) -> RunRecord:
        if m not in runs:
            runs[m] = run_rung(m)
        return runs[m]

    def estimate(m: int) -> float:
        if m not in distances:
            distances[m] = [_distance(run(k), run(m)).max for k in range(m + 1, min(m + 2, ref_n) + 1)]
        return safety * max(distances[m])

    n = start
    if estimate(n) <= tol:
        while n - 1 >= low and estimate(n - 1) <= tol:
            n -= 1
    else:
        while n < top and estimate(n) > tol:
            n += 1
    met = estimate(n) <= tol

    # (c) the reference and its convergence
    ref_dt = reference_dt
    ref_run = run_reference(ref_dt)
    half = run_reference(ref_dt / 2)
    if ref_run.diverged_at is not None or half.diverged_at is not None:
        raise SimulationError(f"the reference {reference} (rk4, dt = {ref_dt:.3g} s) diverged at "
                              f"{ref_run.diverged_at or half.diverged_at:.4g} s on scene '{name}': nothing to judge the "
                              "choice against")
    below = run(ref_n - 1)
    finest = run(ref_n)  # the reference model as a user would run it (its own step): the "always finest" cost
    step_check = _distance(half, ref_run).max
    model_check = _distance(ref_run, below).max
    convergence = {"step_halving_m": step_check, "rung_below_m": model_check, "rung_below": _rung(ref_n - 1),
                   "half_step_run": half.facts()}
    if max(step_check, model_check) > 0.5 * tol:
        warnings.warn(f"the reference {reference} (rk4, dt = {ref_dt:.3g} s) moves by {step_check:.3g} m when its step is "
                      f"halved and differs by {model_check:.3g} m from {_rung(ref_n - 1)}: above half the tolerance "
                      f"{tol:.3g} m, so it may not be converged enough to judge the choice", stacklevel=3)

    rungs = []
    for m in sorted(runs):
        record = runs[m]
        err = _distance(ref_run, record)
        item = {**record.facts(), "reference_error_max_m": err.max, "reference_error_rms_m": err.rms,
                "cost_ratio": record.wall_time_s / ref_run.wall_time_s if ref_run.wall_time_s > 0 else math.inf}
        if m in distances:
            item["distance_to_next_m"] = distances[m][0]
            if len(distances[m]) > 1:
                item["distance_to_second_next_m"] = distances[m][1]
            item["estimated_error_m"] = safety * max(distances[m])
            if m + 1 in distances and distances[m][0] > 0:
                item["ratio_next_distance"] = distances[m + 1][0] / distances[m][0]
        rungs.append(item)

    evidence = {
        "method": ("lowest rung whose safety * (largest tip distance to the next two rungs, up to the reference "
                   "model) <= tolerance; walk from the bandwidth rule's start"),
        "safety": safety, "ladder": [_rung(m) for m in range(low, top + 1)], "bandwidth_rule": rule,
        "reference": {**ref_run.facts(), "convergence": convergence},
        "candidates": rungs, "scene": name, **(extra or {}),
    }
    if not met:
        best = min(distances, key=lambda m: max(distances[m]))
        best_estimate = safety * max(distances[best])
        evidence["best"] = {"rung": _rung(best), "estimated_error_m": best_estimate}
        raise ToleranceUnreachable(
            f"no rung up to amm:{top} meets the tolerance {tol:.3g} m on scene '{name}': the best estimate is "
            f"{best_estimate:.3g} m ({_rung(best)}, {safety:g} x its largest distance to the rungs above); "
            f"allowed: a tolerance >= {best_estimate:.3g} m, or a higher top rung", evidence)

    chosen = run(n)
    err = _distance(ref_run, chosen)
    evidence["cost_ratio_vs_finest"] = chosen.wall_time_s / finest.wall_time_s if finest.wall_time_s > 0 else math.inf
    evidence["finest"] = _rung(ref_n)
    return FidelityChoice(
        choice=parse_fidelity(_rung(n)), tolerance=tol, estimated_error=estimate(n), reference_error=err.max,
        reference_error_rms=err.rms,
        cost_ratio=chosen.wall_time_s / ref_run.wall_time_s if ref_run.wall_time_s > 0 else math.inf,
        integrator=chosen.integrator, dt=chosen.dt, evidence=evidence)


# -- closed-loop scenes -------------------------------------------------------------------------
def sampled_bandwidth(torque: np.ndarray, h: float, *, energy_fraction: float = 0.99) -> float | None:
    """Frequency (Hz) below which ``energy_fraction`` of sampled torques' energy lies.

    Parameters
    ----------
    torque : numpy.ndarray
        Torques (N m), shape (T, n_joints), sampled every ``h`` s; their mean is removed
        first (a held final torque is no excitation), then they are zero-padded to four
        times their length.
    h : float
        Sample period (s).

    Returns
    -------
    float or None
        None when the torques are constant.
    """
    torque = np.asarray(torque, dtype=float)
    torque = torque - torque.mean(axis=0)
    if not np.any(torque):
        return None
    n = torque.shape[0]
    n_fft = 1 << int(math.ceil(math.log2(4 * n)))
    spectrum = np.sum(np.abs(np.fft.rfft(torque, n=n_fft, axis=0)) ** 2, axis=1)
    spectrum[1:] *= 2.0
    cumulative = np.cumsum(spectrum) / spectrum.sum()
    freqs = np.fft.rfftfreq(n_fft, h)
    return float(freqs[min(int(np.searchsorted(cumulative, energy_fraction)), freqs.size - 1)])


def controller_digest(path: str | Path) -> str:
    """sha256 of a controller file's bytes (hex)."""
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def closed_loop_key(scene, controller: str | Path | None = None, overrides: tuple[str, ...] = ()) -> str:
    """A canonical string of everything that changes a closed loop's simulation except the plant fidelity.

    The scene's settings (plant, payload, initial configuration, target, reference,
    design payload / fidelity / configuration, noise and seed, metrics windows), the
    model file's modification time, the controller file's path, sha256 and overrides.
    """
    settings = scene.settings()
    for name in ("fidelity", "tolerance_m", "name", "source", "fft_span", "fft_peaks", "controller"):
        settings.pop(name, None)
    path = Path(scene.plant.model)
    settings["model_mtime_ns"] = path.stat().st_mtime_ns if path.is_file() else None
    ctrl = controller or scene.controller
    settings["controller_file"] = None if ctrl is None else str(Path(ctrl).resolve())
    settings["controller_sha256"] = None if ctrl is None or not Path(ctrl).is_file() else controller_digest(ctrl)
    settings["controller_overrides"] = list(overrides)
    return json.dumps(settings, sort_keys=True, default=str)


class _KeyedLoop:
    """A closed-loop scene with its controller file and overrides, carried through ``lru_cache`` by :func:`closed_loop_key`."""

    def __init__(self, scene, controller, overrides: tuple[str, ...]):
        self.scene, self.controller, self.overrides = scene, controller, tuple(overrides)
        self.key = closed_loop_key(scene, controller, self.overrides)

    def __hash__(self) -> int:
        return hash(self.key)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _KeyedLoop) and other.key == self.key


def simulate_closed_rung(keyed: _KeyedLoop, fidelity: str, dt: float | None = None) -> RunRecord:
    """The closed loop with the plant at ``fidelity`` and RK4 step ``dt`` (s; default method step 4), cached per process.

    The tip is kept on the scene's grid (every ``scene.dt / dt``-th plant sample), so
    every rung is compared on the same times without interpolation.
    """
    scene = keyed.scene.plant
    if dt is None:
        model = _model_for(scene, fidelity)
        dt = rk4_step(model.omega_max, scene.dt)
    return _closed_run_cached(keyed, fidelity, float(dt))


@functools.lru_cache(maxsize=64)
def _closed_run_cached(keyed: _KeyedLoop, fidelity: str, dt: float) -> RunRecord:
    from flexctrl.closedloop import closed_loop_tip_path

    scene = keyed.scene
    stride = int(round(scene.plant.dt / dt))
    result = closed_loop_tip_path(scene, fidelity, dt, controller=keyed.controller, overrides=keyed.overrides,
                                  stride=stride)
    return RunRecord(fidelity=fidelity, integrator="rk4", dt=dt, omega_max=result["omega_max"],
                     wall_time_s=result["wall_time_s"], build_time_s=result["build_time_s"], time=result["time"],
                     tip=result["tip"], diverged_at=result["diverged_at"], torque=result["torque"])


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
) -> FidelityChoice:
    """The lowest plant rung of ``rigid, amm:1 .. amm:top`` estimated to keep a closed loop's tip within ``tol``.

    As :func:`choose_fidelity`, with every candidate a whole closed-loop run: the
    controller (the scene's or ``controller`` with ``overrides``) designed on the
    scene's ``controller_fidelity`` (pinned: the plant's fidelity is what is chosen;
    :func:`flexctrl.closedloop.pin_design` gives ``amm:2`` when the scene names none),
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
        :func:`flexctrl.closedloop.pin_design`).
    tol : float
        Tolerance on the largest tip-position distance (m), > 0.
    controller : str or Path, optional
        Controller file (default: the scene's ``controller``).
    overrides : sequence of str
        ``KEY=VALUE`` overrides of the controller file.
    top, reference, safety, energy_fraction, bandwidth_factor, reference_omega_dt
        As in :func:`choose_fidelity`.

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
        raise SpecError(f"scene kind '{getattr(scene, 'kind', type(scene).__name__)}' is not supported here; allowed: "
                        "a kind = \"closed_loop\" scene (choose_fidelity takes arm scenes)",
                        source=getattr(scene, "source", None), key="kind")
    if scene.controller_fidelity is None or scene.controller_fidelity.kind == "auto":
        raise SpecError(f"value {str(scene.controller_fidelity) if scene.controller_fidelity else None!r} is not allowed "
                        "when the plant is chosen; allowed: a concrete design model, e.g. 'amm:2' "
                        "(flexctrl.closedloop.pin_design sets the default)", source=scene.source, key="controller_fidelity")
    if scene.plant.integrator != "rk4":
        raise SpecError(f"value '{scene.plant.integrator}' is not allowed with fidelity = 'auto' in a closed loop; "
                        "allowed: 'rk4' (the loop integrates the plant with RK4)", source=scene.source, key="integrator")
    if (controller or scene.controller) is None:
        raise SpecError("no controller: give --controller FILE or the scene key 'controller'", source=scene.source,
                        key="controller")
    ref = _check_ladder(top, reference, safety, energy_fraction, bandwidth_factor, reference_omega_dt)
    keyed = _KeyedLoop(scene, controller, tuple(overrides))
    return _choose_closed_cached(keyed, tol, top, str(ref), float(safety), float(energy_fraction),
                                 float(bandwidth_factor), float(reference_omega_dt))


@functools.lru_cache(maxsize=64)
def _choose_closed_cached(keyed: _KeyedLoop, tol: float, top: int, reference: str, safety: float,
                          energy_fraction: float, bandwidth_factor: float, reference_omega_dt: float) -> FidelityChoice:
    started = time.perf_counter()
    scene = keyed.scene
    plant = scene.plant
    low = required_modes(plant)
    if low > top:
        raise SpecError(f"the initial elastic coordinates need {low} modes per link, above the top candidate amm:{top}; "
                        f"allowed: top >= {low}", source=scene.source, key="initial.qf")
    design = scene.controller_fidelity
    design_rung = 0 if design.kind == "rigid" else (design.count or 0) if design.kind == "amm" else top
    first = min(max(low, design_rung), top)
    runs = {first: simulate_closed_rung(keyed, _rung(first))}
    ref_model = _model_for(plant, reference)
    link_hz = [[w / (2 * math.pi) for w in link] for link in ref_model.info.get("link_frequencies_rad_s", [])]
    record = runs[first]
    bandwidth = None
    if record.torque is not None and record.diverged_at is None and record.time.size > 2:
        bandwidth = sampled_bandwidth(record.torque, float(record.time[1] - record.time[0]),
                                      energy_fraction=energy_fraction)
    if bandwidth is None:
        start, kept = first, None
    else:
        limit = bandwidth_factor * bandwidth
        kept = [sum(1 for f in link if f <= limit) for link in link_hz]
        start = min(max([low, *kept]), top)
    rule = {"excitation_bandwidth_hz": bandwidth, "energy_fraction": energy_fraction, "factor": bandwidth_factor,
            "cutoff_hz": None if bandwidth is None else bandwidth_factor * bandwidth,
            "link_mode_frequencies_hz": link_hz, "modes_kept_per_link": kept, "start": _rung(start),
            "lowest_rung_for_initial_state": _rung(low),
            "torques_from": f"the closed loop with the plant at {_rung(first)} (the design model's rung)"}
    ref_dt = plant.dt / max(1, math.ceil(plant.dt * ref_model.omega_max / reference_omega_dt - 1e-12))
    extra = {"kind": "closed_loop", "controller": str(keyed.controller or scene.controller),
             "controller_overrides": list(keyed.overrides), "design_fidelity": str(design),
             "comparison_grid_dt_s": plant.dt}
    choice = _walk_and_judge(
        name=scene.name, tol=tol, low=low, start=start, top=top, reference=reference, safety=safety, rule=rule,
        run_rung=lambda m: simulate_closed_rung(keyed, _rung(m)),
        run_reference=lambda dt: simulate_closed_rung(keyed, reference, dt), reference_dt=ref_dt, runs=runs,
        extra=extra)
    choice.evidence["method"] = ("closed loop (controller designed once on the pinned design model) with the plant at "
                                 "each rung; lowest rung whose safety * (largest tip distance to the next two rungs, up "
                                 "to the reference model) <= tolerance; walk from the bandwidth rule's start")
    choice.evidence["choosing_time_s"] = time.perf_counter() - started
    return choice
