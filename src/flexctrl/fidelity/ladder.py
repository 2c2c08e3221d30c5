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
   scene's step when ``omega_max * dt <= RK4_MARGIN * RK4_STABILITY_LIMIT`` (RK4's stability limit
   with a 10 % margin); otherwise the step is the scene's divided by the
   smallest whole number that satisfies it, so outputs and torque switching
   still fall on the scene's grid.

Every simulation's wall time (``time.perf_counter``, integration only; model
build and compilation recorded apart) is kept; ``cost_ratio`` is the choice's
integration wall time over the reference's.

This module is the method alone: it runs candidates through the callables it is
given (``run_rung``, ``run_reference`` of :func:`walk_and_judge`) and knows no scene
file, model builder or integrator.  Running scenes for it is
:mod:`flexctrl.scenes.auto`'s job (models, runs and choices kept in a
:class:`~flexctrl.scenes.cache.SceneCache` the caller owns).

Examples
--------
>>> from flexctrl.spec.scene import load_scene
>>> from flexctrl.scenes.auto import choose_fidelity
>>> scene = load_scene("studies/scenes/slow_move_light.toml", ["duration=1.0"])
>>> choice = choose_fidelity(scene, 1e-3, top=2, reference="amm:3")  # doctest: +SKIP
>>> str(choice.choice)  # doctest: +SKIP
'rigid'
"""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flexctrl.errors import FlexctrlError, SimulationError, SpecError
from flexctrl.sim.tip_error import TipError, tip_error
from flexctrl.spec.fidelity import FIDELITY_CHECKS, FIDELITY_WALKS, parse_fidelity

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
        facts = {
            "fidelity": self.fidelity,
            "integrator": self.integrator,
            "dt_s": self.dt,
            "omega_max_rad_s": self.omega_max,
            "omega_max_dt": self.omega_max * self.dt,
            "wall_time_s": self.wall_time_s,
            "build_time_s": self.build_time_s,
        }
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
            "choice": str(self.choice),
            "tolerance_m": self.tolerance,
            "estimated_error": self.estimated_error,
            "reference_error": self.reference_error,
            "reference_error_rms": self.reference_error_rms,
            "cost_ratio": self.cost_ratio,
            "integrator": self.integrator,
            "dt_s": self.dt,
            **self.evidence,
        }


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


# -- closed-loop scenes -------------------------------------------------------------------------
def sampled_bandwidth(
    torque: np.ndarray, h: float, *, energy_fraction: float = 0.99
) -> float | None:
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


def required_modes(scene) -> int:
    """Fewest modes per link that hold the scene's initial elastic coordinates (``qf<link><mode>``)."""
    need = 0
    for name in scene.qf0:
        match = _QF.match(name)
        if match:
            need = max(need, int(match.group(2)))
    return need


def rung_name(n: int) -> str:
    return "rigid" if n == 0 else f"amm:{n}"


def tip_distance(a: RunRecord, b: RunRecord):
    """Tip distance of ``b`` from ``a`` on ``a``'s samples (the finer run goes first); infinite if either diverged."""
    if a.diverged_at is not None or b.diverged_at is not None:
        return TipError(rms=math.inf, max=math.inf)
    first, second = (a, b) if a.dt <= b.dt else (b, a)
    return tip_error(first.time, first.tip, second.time, second.tip)


# -- the method -------------------------------------------------------------------------------
METHOD = (
    "lowest rung whose safety * (largest tip distance to the next two rungs, up to the reference model) <= "
    "tolerance; walk from the bandwidth rule's start"
)


#: Bound assumed on the linear estimate's error either way: a rung whose linear estimate exceeds ``LINEAR_FACTOR``
#: times the tolerance is not certified (measured on the quickstart's loops: nonlinear / linear estimate 0.43-1.17,
#: docs/auto_fidelity.md; tests/test_fidelity_estimate.py checks a small case).
LINEAR_FACTOR = 3.0
#: The walks of the closed-loop chooser (:data:`flexctrl.spec.fidelity.FIDELITY_WALKS`).
WALKS = FIDELITY_WALKS
METHOD_ESTIMATE = (
    "linear estimate of every rung (the loop on each rung's linearised plant at its own RK4 step), then "
    "the lowest rung it cannot exclude certified by nonlinear runs: lowest rung whose safety * (largest "
    "tip distance to the next two rungs, up to the reference model) <= tolerance, walking up"
)


METHOD_FROM_TOP = (
    "nonlinear runs from the top rung down (the controller steps in Python: a linear run would cost as much "
    "as a nonlinear one): the lowest rung of the unbroken run from the top whose safety * (largest tip "
    "distance to the next two rungs, up to the reference model) <= tolerance"
)


def _method(linear, from_top: bool) -> str:
    return METHOD_FROM_TOP if from_top else METHOD if linear is None else METHOD_ESTIMATE


def linear_candidate(
    linear_rung,
    *,
    tol: float,
    low: int,
    top: int,
    ref_n: int,
    safety: float,
    factor: float = LINEAR_FACTOR,
) -> tuple[int | None, dict[str, Any]]:
    """The lowest rung whose linear estimate is within ``factor`` of the tolerance, and the evidence.

    The linear estimate of rung ``m`` is the walk's formula (``safety`` times the largest
    tip distance to rungs ``m + 1`` and ``m + 2``, up to ``ref_n``) on the linear runs
    ``linear_rung(m)``.  Rungs are estimated from the top down while their estimate is
    at most ``factor * tol``; the lowest of that unbroken run of rungs is the candidate.
    When ``top`` is excluded, the rungs below are estimated until one is not (the
    candidate is then the lowest of its unbroken run), or None when every rung is
    excluded (unreachable, as predicted, without a nonlinear run).
    A rung that cannot be built (``FlexctrlError``, e.g. strain gauges on ``rigid``) is excluded.
    """
    runs: dict[int, RunRecord | str] = {}

    def run(m: int):
        if m not in runs:
            try:
                runs[m] = linear_rung(m)
            except FlexctrlError as exc:
                runs[m] = str(exc)
        return runs[m]

    estimates: dict[int, float] = {}

    def estimate(m: int) -> float:
        if m not in estimates:
            pair = [run(k) for k in range(m + 1, min(m + 2, ref_n) + 1)]
            here = run(m)
            if isinstance(here, str) or any(isinstance(p, str) for p in pair):
                estimates[m] = math.inf
            else:
                estimates[m] = safety * max(tip_distance(p, here).max for p in pair)
        return estimates[m]

    n = None
    for m in range(top, low - 1, -1):
        if estimate(m) <= factor * tol:
            n = m
        elif n is not None:
            break
    rungs = []
    for m in sorted(runs):
        item = {"fidelity": rung_name(m)}
        if isinstance(runs[m], str):
            item["unavailable"] = runs[m]
        else:
            item.update(runs[m].facts())
        if m in estimates:
            item["estimated_error_m"] = estimates[m]
        rungs.append(item)
    evidence = {
        "factor": factor,
        "threshold_m": factor * tol,
        "candidate": None if n is None else rung_name(n),
        "rungs": rungs,
        "wall_time_s": sum(
            r.wall_time_s + r.build_time_s for r in runs.values() if not isinstance(r, str)
        ),
    }
    return n, evidence


def _buildable_estimate(estimate, m: int) -> float:
    """``estimate(m)``, infinite when rung ``m`` cannot be built (``SpecError``, e.g. strain gauges on ``rigid``).

    Only a rung that cannot be built stops the walk this way; a solver or simulation
    failure on it is raised, as the other walks raise it.
    """
    try:
        return estimate(m)
    except SpecError:
        return math.inf


def _estimates(m: int, distances: dict[int, list[float]], safety: float) -> dict[str, float]:
    """Rung ``m``'s distances to the rungs above and its estimate (empty when it was not estimated)."""
    if m not in distances:
        return {}
    item = {"distance_to_next_m": distances[m][0]}
    if len(distances[m]) > 1:
        item["distance_to_second_next_m"] = distances[m][1]
    item["estimated_error_m"] = safety * max(distances[m])
    if m + 1 in distances and distances[m][0] > 0:
        item["ratio_next_distance"] = distances[m + 1][0] / distances[m][0]
    return item


def check_ladder(top, reference, safety, energy_fraction, bandwidth_factor, reference_omega_dt):
    """Validate the chooser's options (shared by the arm and closed-loop choosers); returns the reference fidelity."""
    if isinstance(top, bool) or not isinstance(top, int) or not 1 <= top <= 5:
        raise SpecError(
            f"value {top!r} is not allowed; allowed: an integer 1..5 (amm:top is the highest candidate)",
            key="top",
        )
    ref = parse_fidelity(reference if reference is not None else f"amm:{top + 1}", key="reference")
    if ref.kind != "amm" or not top < (ref.count or 0) <= 6:
        raise SpecError(
            f"value '{ref}' is not allowed; allowed: 'amm:R' with {top} < R <= 6 (above the top candidate amm:{top})",
            key="reference",
        )
    for name, value, low, high in (
        ("safety", safety, 1.0, 100.0),
        ("energy_fraction", energy_fraction, 0.0, 1.0),
        ("bandwidth_factor", bandwidth_factor, 0.0, 1e3),
        ("reference_omega_dt", reference_omega_dt, 0.0, 2.5),
    ):
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not low <= value <= high
            or value == 0
        ):
            raise SpecError(
                f"value {value!r} is not allowed; allowed: a number in ({low:g}, {high:g}]",
                key=name,
            )
    return ref


def check_tolerance(tol: Any, *, source: str | None = None, key: str = "tolerance") -> float:
    """``tol`` as a float if it is a finite number > 0 (m), else :class:`SpecError`."""
    if (
        isinstance(tol, bool)
        or not isinstance(tol, (int, float))
        or not math.isfinite(tol)
        or tol <= 0
    ):
        raise SpecError(
            f"value {tol!r} is not allowed; allowed: a finite number > 0 (m, tip-position tolerance)",
            source=source,
            key=key,
        )
    return float(tol)


def walk_and_judge(
    *,
    name: str,
    tol: float,
    low: int,
    start: int,
    top: int,
    reference: str,
    safety: float,
    rule: dict[str, Any],
    run_rung,
    run_reference,
    reference_dt: float,
    runs: dict[int, RunRecord] | None = None,
    extra: dict[str, Any] | None = None,
    linear=None,
    factor: float = LINEAR_FACTOR,
    from_top: bool = False,
    checks: str = "full",
) -> FidelityChoice:
    """Method steps 2 and 3, shared by arm and closed-loop scenes.

    With ``linear`` (the estimate-first walk, :func:`linear_candidate`), the walk starts
    at the lowest rung the linear estimate cannot exclude, or stops before any
    nonlinear run when it excludes every rung, and the reference is the reference model
    at its own step (``run_rung(R)``, a run the certification usually needs anyway)
    instead of ``run_reference`` at ``reference_dt`` and half of it.

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
    linear : tuple, optional
        ``(linear_rung, linear_exact)``: ``linear_rung(m) -> RunRecord`` the linear
        estimate of rung ``m`` at its own step (raising :class:`FlexctrlError` when the
        rung cannot be built), ``linear_exact() -> RunRecord`` the reference model's
        without integrator error.  None: the ladder walk from ``start``.
    factor : float
        Bound assumed on the linear estimate's error, either way (``LINEAR_FACTOR``).
    from_top : bool
        The estimate walk for loops whose linear run costs what the nonlinear one does
        (a controller stepped in Python): no linear estimate of the rungs; the nonlinear
        walk starts at ``top`` and goes down while the rung below meets the tolerance (the
        lowest rung of the unbroken run of rungs from the top that meet it; ``top``
        failing is a measured :class:`ToleranceUnreachable`). The reference and its
        linear step check are the estimate walk's (``linear`` is still needed for them).
    checks : {"full", "tolerance"}
        ``full``: the walks from the top and the ladder's go down while the rung below
        meets the tolerance (the choice is the lowest that does), and the reference's
        convergence is checked (its step; the rung below it).  ``tolerance``: only the
        runs that certify the tolerance: no rung below a rung that meets it is tried (the
        choice may be higher than needed; the estimate-first walk's candidate is still the
        lowest its linear estimate allows), no step check, the distance from the rung below
        the reference and the ladder walk's finest run at its own step (its cost ratio) only
        when run anyway.  The evidence says which.
    """
    if checks not in FIDELITY_CHECKS:
        raise ValueError(f"checks {checks!r}: allowed {' or '.join(map(repr, FIDELITY_CHECKS))}")
    full = checks == "full"
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
            distances[m] = [
                tip_distance(run(k), run(m)).max for k in range(m + 1, min(m + 2, ref_n) + 1)
            ]
        return safety * max(distances[m])

    linear_evidence = None
    if from_top:
        if linear is None:
            raise ValueError("from_top needs the linear runs for the reference's step check")
        n = top
        while (
            full
            and n - 1 >= low
            and estimate(n) <= tol
            and _buildable_estimate(estimate, n - 1) <= tol
        ):
            n -= 1
    elif linear is None:
        n = start
        if estimate(n) <= tol:
            while full and n - 1 >= low and estimate(n - 1) <= tol:
                n -= 1
        else:
            while n < top and estimate(n) > tol:
                n += 1
    else:
        n, linear_evidence = linear_candidate(
            linear[0], tol=tol, low=low, top=top, ref_n=ref_n, safety=safety, factor=factor
        )
        extra = {**(extra or {}), "linear_estimate": linear_evidence}
        if n is None:
            best = min(
                linear_evidence["rungs"], key=lambda item: item.get("estimated_error_m", math.inf)
            )
            raise ToleranceUnreachable(
                f"no rung up to amm:{top} meets the tolerance {tol:.3g} m on scene '{name}', predicted by the linear "
                f"estimate: its best is {best.get('estimated_error_m', math.inf):.3g} m ({best['fidelity']}), above "
                f"{factor:g} x the tolerance (the bound assumed on its error), so no nonlinear run was made; allowed: a "
                f"tolerance >= {best.get('estimated_error_m', math.inf) / factor:.3g} m, a higher top rung, or "
                "fidelity_walk = 'ladder'",
                {
                    "method": METHOD_ESTIMATE,
                    "checks": checks,
                    "safety": safety,
                    "scene": name,
                    "reference": None,
                    "candidates": [],
                    "bandwidth_rule": rule,
                    **extra,
                    "predicted": True,
                    "best": {
                        "rung": best["fidelity"],
                        "estimated_error_m": best.get("estimated_error_m"),
                        "from": "linear estimate",
                    },
                },
            )
        while n < top and estimate(n) > tol:
            n += 1
    met = estimate(n) <= tol

    # nothing meets the tolerance: no reference is needed to judge a choice (it costs the most)
    if not met:
        best = min(distances, key=lambda m: max(distances[m]))
        best_estimate = safety * max(distances[best])
        evidence = {
            "method": _method(linear, from_top),
            "checks": checks,
            "safety": safety,
            "ladder": [rung_name(m) for m in range(low, top + 1)],
            "bandwidth_rule": rule,
            "candidates": [
                {**runs[m].facts(), **_estimates(m, distances, safety)} for m in sorted(runs)
            ],
            "scene": name,
            "reference": None,
            **(extra or {}),
            "best": {"rung": rung_name(best), "estimated_error_m": best_estimate},
        }
        if from_top:
            raise ToleranceUnreachable(
                f"the top rung amm:{top} does not meet the tolerance {tol:.3g} m on scene '{name}': its estimate is "
                f"{best_estimate:.3g} m ({safety:g} x its largest distance to the rungs above); the walk from the top "
                "tries no rung below a top that fails; allowed: a tolerance >= "
                f"{best_estimate:.3g} m, a higher top rung, or fidelity_walk = 'ladder' (it tries the "
                "rungs below)",
                evidence,
            )
        raise ToleranceUnreachable(
            f"no rung up to amm:{top} meets the tolerance {tol:.3g} m on scene '{name}': the best estimate is "
            f"{best_estimate:.3g} m ({rung_name(best)}, {safety:g} x its largest distance to the rungs above); "
            f"allowed: a tolerance >= {best_estimate:.3g} m, or a higher top rung",
            evidence,
        )

    # (c) the reference and its convergence
    # the reference model as a user would run it (its own step): the "always finest" cost; in the ladder walk only
    # evidence (its cost ratio), so not run for it with checks = "tolerance"
    finest = run(ref_n) if full or linear is not None or ref_n in runs else None
    if linear is None:
        ref_dt = reference_dt
        ref_run = run_reference(ref_dt)
        half = run_reference(ref_dt / 2) if full else ref_run
    else:  # the estimate-first walk: the reference model at its own step, its step error estimated linearly
        ref_dt, ref_run, half = finest.dt, finest, finest
    if ref_run.diverged_at is not None or half.diverged_at is not None:
        raise SimulationError(
            f"the reference {reference} (rk4, dt = {ref_dt:.3g} s) diverged at "
            f"{ref_run.diverged_at or half.diverged_at:.4g} s on scene '{name}': nothing to judge the "
            "choice against"
        )
    below = run(ref_n - 1) if full or ref_n - 1 in runs else None
    model_check = 0.0 if below is None else tip_distance(ref_run, below).max
    if not full:
        step_check, convergence = 0.0, {"step_check": "not made (fidelity_checks = 'tolerance')"}
    elif linear is None:
        step_check = tip_distance(half, ref_run).max
        convergence = {"step_halving_m": step_check, "half_step_run": half.facts()}
    else:
        exact = linear[1]()
        step_check = tip_distance(exact, linear[0](ref_n)).max
        convergence = {
            "step_error_linear_m": step_check,
            "step_check": "linear estimate: the reference model's linear loop at its own RK4 step against "
            "the same loop without integrator error (zero-order hold)",
        }
        if linear_evidence is not None:
            linear_evidence["reference_exact"] = exact.facts()
        else:
            convergence["reference_exact"] = exact.facts()
    convergence.update(
        {"rung_below_m": None if below is None else model_check, "rung_below": rung_name(ref_n - 1)}
    )
    if max(step_check, model_check) > 0.5 * tol:
        moves = (
            f"moves by {step_check:.3g} m with {'half its step' if linear is None else 'no integrator error (linear estimate)'}"
            " and "
            if full
            else ""
        )
        warnings.warn(
            f"the reference {reference} (rk4, dt = {ref_dt:.3g} s) {moves}differs by {model_check:.3g} m from "
            f"{rung_name(ref_n - 1)}: above half the tolerance {tol:.3g} m, so it may not be converged enough to "
            "judge the choice",
            stacklevel=3,
        )

    rungs = []
    for m in sorted(runs):
        record = runs[m]
        err = tip_distance(ref_run, record)
        item = {
            **record.facts(),
            "reference_error_max_m": err.max,
            "reference_error_rms_m": err.rms,
            "cost_ratio": record.wall_time_s / ref_run.wall_time_s
            if ref_run.wall_time_s > 0
            else math.inf,
        }
        rungs.append({**item, **_estimates(m, distances, safety)})

    evidence = {
        "method": _method(linear, from_top),
        "checks": checks,
        "safety": safety,
        "ladder": [rung_name(m) for m in range(low, top + 1)],
        "bandwidth_rule": rule,
        "reference": {
            **ref_run.facts(),
            "convergence": convergence,
            "role": (
                "the reference model at omega_max * dt <= reference_omega_dt"
                if linear is None
                else "the reference model at its own RK4 step (fidelity_walk = 'estimate')"
            ),
        },
        "candidates": rungs,
        "scene": name,
        **(extra or {}),
    }
    chosen = run(n)
    err = tip_distance(ref_run, chosen)
    evidence["cost_ratio_vs_finest"] = (
        None
        if finest is None
        else chosen.wall_time_s / finest.wall_time_s
        if finest.wall_time_s > 0
        else math.inf
    )
    evidence["finest"] = rung_name(ref_n)
    return FidelityChoice(
        choice=parse_fidelity(rung_name(n)),
        tolerance=tol,
        estimated_error=estimate(n),
        reference_error=err.max,
        reference_error_rms=err.rms,
        cost_ratio=chosen.wall_time_s / ref_run.wall_time_s
        if ref_run.wall_time_s > 0
        else math.inf,
        integrator=chosen.integrator,
        dt=chosen.dt,
        evidence=evidence,
    )
