"""The walk over the ladder and its judgement: steps 2 and 3 of :mod:`flexctrl.fidelity.ladder`.

:func:`walk_and_judge` is given what to answer (a :class:`Ladder`: the rungs, the
tolerance, how strictly to check) and how to get runs (:class:`Runners`: callables that
simulate a rung, the reference, and the linear estimates), walks the rungs one of three
ways (:data:`WALK_KINDS`) and judges the choice against the reference.  It knows no scene
file, model builder or integrator.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from flexctrl.errors import SimulationError, SpecError
from flexctrl.fidelity.linear_candidate import LINEAR_FACTOR, linear_candidate
from flexctrl.fidelity.records import FidelityChoice, RunRecord, ToleranceUnreachable
from flexctrl.fidelity.rungs import rung_name, tip_distance
from flexctrl.spec.fidelity import FIDELITY_CHECKS, parse_fidelity

METHOD = (
    "lowest rung whose safety * (largest tip distance to the next two rungs, up to the reference "
    "model) <= tolerance; walk from the bandwidth rule's start"
)
METHOD_ESTIMATE = (
    "linear estimate of every rung (the loop on each rung's linearised plant at its own RK4 "
    "step), then the lowest rung it cannot exclude certified by nonlinear runs: lowest rung whose "
    "safety * (largest tip distance to the next two rungs, up to the reference model) <= "
    "tolerance, walking up"
)
METHOD_FROM_TOP = (
    "nonlinear runs from the top rung down (the controller steps in Python: a linear run would "
    "cost as much as a nonlinear one): the lowest rung of the unbroken run from the top whose "
    "safety * (largest tip distance to the next two rungs, up to the reference model) <= tolerance"
)
#: How :func:`walk_and_judge` walks: ``ladder`` (nonlinear runs from a start, the reference at a
#: given step and half of it), ``linear_first`` (the lowest rung the linear estimates cannot
#: exclude, certified walking up) and ``from_top`` (nonlinear runs from the top rung down, for
#: loops whose linear runs cost what nonlinear ones do).  The last two judge against the
#: reference model at its own step and estimate its step error linearly.
WALK_KINDS = ("ladder", "linear_first", "from_top")


@dataclass(frozen=True)
class Ladder:
    """What the walk answers: the lowest rung within the tolerance, and how strictly it checks.

    Attributes
    ----------
    name : str
        The scene's name (for messages and the evidence).
    tol : float
        Tolerance on the largest tip distance (m).
    low : int
        The lowest rung (modes per link; 0 = rigid).
    top : int
        The highest candidate rung.
    reference : str
        The reference model, ``amm:R`` with ``R > top``.
    safety : float
        Factor on the largest distance to the next two rungs that makes the estimate.
    checks : {"full", "tolerance"}
        ``full``: the walks go down while the rung below meets the tolerance (the choice is
        the lowest that does), and the reference's convergence is checked (its step; the
        rung below it).  ``tolerance``: only the runs that certify the tolerance: no rung
        below a rung that meets it is tried (the choice may be higher than needed; the
        linear-first walk's candidate is still the lowest its linear estimate allows), no
        step check, the distance from the rung below the reference and the ladder walk's
        finest run at its own step (its cost ratio) only when run anyway.
    factor : float
        Bound assumed on the linear estimate's error, either way.
    """

    name: str
    tol: float
    low: int
    top: int
    reference: str
    safety: float = 2.0
    checks: str = "full"
    factor: float = LINEAR_FACTOR

    @property
    def ref_n(self) -> int:
        """The reference model's modes per link."""
        return parse_fidelity(self.reference).count or 0


@dataclass(frozen=True)
class Runners:
    """How the walk gets runs; each returns a :class:`~flexctrl.fidelity.records.RunRecord`.

    Attributes
    ----------
    rung : callable
        ``rung(m)``: rung ``m`` (0 = rigid) with its own integrator and step.
    reference : callable, optional
        ``reference(dt)``: the reference model with RK4 at step ``dt`` (s); the ladder walk's.
    reference_dt : float, optional
        The ladder walk's reference step (s).
    linear_rung : callable, optional
        ``linear_rung(m)``: the linear estimate of rung ``m`` at its own step (raising
        :class:`~flexctrl.errors.FlexctrlError` when the rung cannot be built); the other
        walks'.
    linear_exact : callable, optional
        ``linear_exact()``: the reference model's linear loop without integrator error.
    """

    rung: Callable[[int], RunRecord]
    reference: Callable[[float], RunRecord] | None = None
    reference_dt: float | None = None
    linear_rung: Callable[[int], RunRecord] | None = None
    linear_exact: Callable[[], RunRecord] | None = None


def walk_and_judge(
    ladder: Ladder,
    runners: Runners,
    *,
    walk: str = "ladder",
    start: int | None = None,
    rule: dict[str, Any] | None = None,
    runs: dict[int, RunRecord] | None = None,
    extra: dict[str, Any] | None = None,
) -> FidelityChoice:
    """Walk the ladder, choose the lowest rung within the tolerance, and judge it.

    Parameters
    ----------
    ladder : Ladder
        The rungs, the tolerance and how strictly to check.
    runners : Runners
        The runs: ``rung`` always; ``reference`` and ``reference_dt`` for the ladder walk;
        ``linear_rung`` and ``linear_exact`` for the other two.
    walk : {"ladder", "linear_first", "from_top"}
        :data:`WALK_KINDS`.
    start : int, optional
        The ladder walk's first rung (the bandwidth rule's).
    rule : dict, optional
        The bandwidth rule's evidence.
    runs : dict, optional
        Rungs already run (by rung number).
    extra : dict, optional
        Added to the evidence.

    Returns
    -------
    FidelityChoice
        The choice, its estimate and its distance from the reference, and the evidence.

    Raises
    ------
    ToleranceUnreachable
        When no rung meets the tolerance (measured, or predicted by the linear estimates).
    SimulationError
        When the reference diverges.
    """
    if ladder.checks not in FIDELITY_CHECKS:
        raise ValueError(
            f"checks {ladder.checks!r}: allowed {' or '.join(map(repr, FIDELITY_CHECKS))}"
        )
    if walk not in WALK_KINDS:
        raise ValueError(f"walk {walk!r}: allowed {', '.join(map(repr, WALK_KINDS))}")
    if walk != "ladder" and (runners.linear_rung is None or runners.linear_exact is None):
        raise ValueError(f"the {walk} walk needs the linear runs for the reference's step check")
    state = _Walk(ladder, runners, walk, rule or {}, runs, extra)
    if walk == "from_top":
        n = state.from_top()
    elif walk == "linear_first":
        n = state.linear_first()
    else:
        n = state.from_start(ladder.top if start is None else start)
    if state.estimate(n) > ladder.tol:
        raise state.unreachable()
    return state.judge(n)


_METHODS = {"ladder": METHOD, "linear_first": METHOD_ESTIMATE, "from_top": METHOD_FROM_TOP}


class _Walk:
    """One walk: the runs made (kept by rung), the distances measured, and the judgement."""

    def __init__(self, ladder: Ladder, runners: Runners, walk: str, rule, runs, extra):
        self.ladder, self.runners, self.walk, self.rule = ladder, runners, walk, rule
        self.runs: dict[int, RunRecord] = dict(runs or {})
        self.extra: dict[str, Any] = dict(extra or {})
        self.distances: dict[int, list[float]] = {}
        self.linear_evidence: dict[str, Any] | None = None

    @property
    def full(self) -> bool:
        return self.ladder.checks == "full"

    def run(self, m: int) -> RunRecord:
        """Rung ``m``'s run, made once."""
        if m not in self.runs:
            self.runs[m] = self.runners.rung(m)
        return self.runs[m]

    def estimate(self, m: int) -> float:
        """``safety`` times rung ``m``'s largest tip distance to the next two rungs (m)."""
        if m not in self.distances:
            above = range(m + 1, min(m + 2, self.ladder.ref_n) + 1)
            self.distances[m] = [tip_distance(self.run(k), self.run(m)).max for k in above]
        return self.ladder.safety * max(self.distances[m])

    # -- the three walks ----------------------------------------------------------------------
    def from_start(self, start: int) -> int:
        """The ladder walk: up from ``start`` while it fails, or down while the rung below meets."""
        L, n = self.ladder, start
        if self.estimate(n) <= L.tol:
            while self.full and n - 1 >= L.low and self.estimate(n - 1) <= L.tol:
                n -= 1
        else:
            while n < L.top and self.estimate(n) > L.tol:
                n += 1
        return n

    def from_top(self) -> int:
        """Down from the top while the rung below meets the tolerance (and can be built)."""
        L, n = self.ladder, self.ladder.top
        while (
            self.full
            and n - 1 >= L.low
            and self.estimate(n) <= L.tol
            and _buildable_estimate(self.estimate, n - 1) <= L.tol
        ):
            n -= 1
        return n

    def linear_first(self) -> int:
        """The linear estimates' candidate, certified by nonlinear runs walking up."""
        L = self.ladder
        assert self.runners.linear_rung is not None  # checked by walk_and_judge
        n, evidence = linear_candidate(
            self.runners.linear_rung,
            tol=L.tol,
            low=L.low,
            top=L.top,
            ref_n=L.ref_n,
            safety=L.safety,
            factor=L.factor,
        )
        self.linear_evidence = evidence
        self.extra["linear_estimate"] = evidence
        if n is None:
            raise self.predicted_unreachable(evidence)
        while n < L.top and self.estimate(n) > L.tol:
            n += 1
        return n

    # -- no rung meets the tolerance ------------------------------------------------------------
    def predicted_unreachable(self, evidence: dict[str, Any]) -> ToleranceUnreachable:
        """The linear estimates exclude every rung: unreachable without a nonlinear run."""
        L = self.ladder
        best = min(evidence["rungs"], key=lambda item: item.get("estimated_error_m", math.inf))
        best_error = best.get("estimated_error_m", math.inf)
        message = (
            f"no rung up to amm:{L.top} meets the tolerance {L.tol:.3g} m on scene '{L.name}', "
            f"predicted by the linear estimate: its best is {best_error:.3g} m "
            f"({best['fidelity']}), above {L.factor:g} x the tolerance (the bound assumed on its "
            "error), so no nonlinear run was made; allowed: a tolerance >= "
            f"{best_error / L.factor:.3g} m, a higher top rung, or fidelity_walk = 'ladder'"
        )
        return ToleranceUnreachable(
            message,
            {
                "method": METHOD_ESTIMATE,
                "checks": L.checks,
                "safety": L.safety,
                "scene": L.name,
                "reference": None,
                "candidates": [],
                "bandwidth_rule": self.rule,
                **self.extra,
                "predicted": True,
                "best": {
                    "rung": best["fidelity"],
                    "estimated_error_m": best.get("estimated_error_m"),
                    "from": "linear estimate",
                },
            },
        )

    def unreachable(self) -> ToleranceUnreachable:
        """No rung walked meets the tolerance: the measured failure, naming the best estimate."""
        L, distances = self.ladder, self.distances
        best = min(distances, key=lambda m: max(distances[m]))
        best_estimate = L.safety * max(distances[best])
        evidence = {
            "method": _METHODS[self.walk],
            "checks": L.checks,
            "safety": L.safety,
            "ladder": [rung_name(m) for m in range(L.low, L.top + 1)],
            "bandwidth_rule": self.rule,
            "candidates": [
                {**self.runs[m].facts(), **_estimates(m, distances, L.safety)}
                for m in sorted(self.runs)
            ],
            "scene": L.name,
            "reference": None,
            **self.extra,
            "best": {"rung": rung_name(best), "estimated_error_m": best_estimate},
        }
        if self.walk == "from_top":
            message = (
                f"the top rung amm:{L.top} does not meet the tolerance {L.tol:.3g} m on scene "
                f"'{L.name}': its estimate is {best_estimate:.3g} m ({L.safety:g} x its largest "
                "distance to the rungs above); the walk from the top tries no rung below a top "
                f"that fails; allowed: a tolerance >= {best_estimate:.3g} m, a higher top rung, or "
                "fidelity_walk = 'ladder' (it tries the rungs below)"
            )
        else:
            message = (
                f"no rung up to amm:{L.top} meets the tolerance {L.tol:.3g} m on scene "
                f"'{L.name}': the best estimate is {best_estimate:.3g} m ({rung_name(best)}, "
                f"{L.safety:g} x its largest distance to the rungs above); allowed: a tolerance "
                f">= {best_estimate:.3g} m, or a higher top rung"
            )
        return ToleranceUnreachable(message, evidence)

    # -- the reference and the choice -----------------------------------------------------------
    def judge(self, n: int) -> FidelityChoice:
        """Rung ``n`` (which meets the tolerance) judged against the reference, with evidence."""
        L, ref_n = self.ladder, self.ladder.ref_n
        # the reference model as a user would run it (its own step): the "always finest" cost; in
        # the ladder walk only evidence (its cost ratio), so not run for it with checks =
        # "tolerance"
        finest = (
            self.run(ref_n) if self.full or self.walk != "ladder" or ref_n in self.runs else None
        )
        ref_run, half, ref_dt = self._reference(finest)
        below = self.run(ref_n - 1) if self.full or ref_n - 1 in self.runs else None
        model_check = 0.0 if below is None else tip_distance(ref_run, below).max
        step_check, convergence = self._step_check(ref_run, half)
        convergence.update(
            {
                "rung_below_m": None if below is None else model_check,
                "rung_below": rung_name(ref_n - 1),
            }
        )
        if max(step_check, model_check) > 0.5 * L.tol:
            self._warn_unconverged(ref_dt, step_check, model_check)
        evidence = self._evidence(ref_run, convergence)
        chosen = self.run(n)
        err = tip_distance(ref_run, chosen)
        evidence["cost_ratio_vs_finest"] = (
            None if finest is None else _ratio(chosen.wall_time_s, finest.wall_time_s)
        )
        evidence["finest"] = rung_name(ref_n)
        return FidelityChoice(
            choice=parse_fidelity(rung_name(n)),
            tolerance=L.tol,
            estimated_error=self.estimate(n),
            reference_error=err.max,
            reference_error_rms=err.rms,
            cost_ratio=_ratio(chosen.wall_time_s, ref_run.wall_time_s),
            integrator=chosen.integrator,
            dt=chosen.dt,
            evidence=evidence,
        )

    def _reference(self, finest: RunRecord | None) -> tuple[RunRecord, RunRecord, float]:
        """The reference run, its half-step run (the ladder walk's) and its step (s)."""
        if self.walk == "ladder":
            reference, ref_dt = self.runners.reference, self.runners.reference_dt
            assert reference is not None and ref_dt is not None, "the ladder walk's reference"
            ref_run = reference(ref_dt)
            half = reference(ref_dt / 2) if self.full else ref_run
        else:  # the reference model at its own step, its step error estimated linearly
            assert finest is not None
            ref_dt, ref_run, half = finest.dt, finest, finest
        if ref_run.diverged_at is not None or half.diverged_at is not None:
            raise SimulationError(
                f"the reference {self.ladder.reference} (rk4, dt = {ref_dt:.3g} s) diverged at "
                f"{ref_run.diverged_at or half.diverged_at:.4g} s on scene '{self.ladder.name}': "
                "nothing to judge the choice against"
            )
        return ref_run, half, ref_dt

    def _step_check(self, ref_run: RunRecord, half: RunRecord) -> tuple[float, dict[str, Any]]:
        """How far the reference moves with its step refined (m), and the evidence of it."""
        if not self.full:
            return 0.0, {"step_check": "not made (fidelity_checks = 'tolerance')"}
        if self.walk == "ladder":
            step_check = tip_distance(half, ref_run).max
            return step_check, {"step_halving_m": step_check, "half_step_run": half.facts()}
        linear_rung, linear_exact = self.runners.linear_rung, self.runners.linear_exact
        assert linear_rung is not None and linear_exact is not None  # checked by walk_and_judge
        exact = linear_exact()
        step_check = tip_distance(exact, linear_rung(self.ladder.ref_n)).max
        convergence: dict[str, Any] = {
            "step_error_linear_m": step_check,
            "step_check": "linear estimate: the reference model's linear loop at its own RK4 step "
            "against the same loop without integrator error (zero-order hold)",
        }
        if self.linear_evidence is not None:
            self.linear_evidence["reference_exact"] = exact.facts()
        else:
            convergence["reference_exact"] = exact.facts()
        return step_check, convergence

    def _warn_unconverged(self, ref_dt: float, step_check: float, model_check: float) -> None:
        L = self.ladder
        refined = (
            "half its step" if self.walk == "ladder" else "no integrator error (linear estimate)"
        )
        moves = f"moves by {step_check:.3g} m with {refined} and " if self.full else ""
        warnings.warn(
            f"the reference {L.reference} (rk4, dt = {ref_dt:.3g} s) {moves}differs by "
            f"{model_check:.3g} m from {rung_name(L.ref_n - 1)}: above half the tolerance "
            f"{L.tol:.3g} m, so it may not be converged enough to judge the choice",
            stacklevel=5,  # the caller of walk_and_judge's caller (the chooser's user)
        )

    def _evidence(self, ref_run: RunRecord, convergence: dict[str, Any]) -> dict[str, Any]:
        """Everything measured: the rule, every rung's run and estimate, the reference."""
        L = self.ladder
        rungs = []
        for m in sorted(self.runs):
            record = self.runs[m]
            err = tip_distance(ref_run, record)
            item = {
                **record.facts(),
                "reference_error_max_m": err.max,
                "reference_error_rms_m": err.rms,
                "cost_ratio": _ratio(record.wall_time_s, ref_run.wall_time_s),
            }
            rungs.append({**item, **_estimates(m, self.distances, L.safety)})
        role = (
            "the reference model at omega_max * dt <= reference_omega_dt"
            if self.walk == "ladder"
            else "the reference model at its own RK4 step (fidelity_walk = 'estimate')"
        )
        return {
            "method": _METHODS[self.walk],
            "checks": L.checks,
            "safety": L.safety,
            "ladder": [rung_name(m) for m in range(L.low, L.top + 1)],
            "bandwidth_rule": self.rule,
            "reference": {**ref_run.facts(), "convergence": convergence, "role": role},
            "candidates": rungs,
            "scene": L.name,
            **self.extra,
        }


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 else math.inf


def _estimates(m: int, distances: dict[int, list[float]], safety: float) -> dict[str, float]:
    """Rung ``m``'s distances to the rungs above and its estimate (empty when not estimated)."""
    if m not in distances:
        return {}
    item = {"distance_to_next_m": distances[m][0]}
    if len(distances[m]) > 1:
        item["distance_to_second_next_m"] = distances[m][1]
    item["estimated_error_m"] = safety * max(distances[m])
    if m + 1 in distances and distances[m][0] > 0:
        item["ratio_next_distance"] = distances[m + 1][0] / distances[m][0]
    return item


def _buildable_estimate(estimate: Callable[[int], float], m: int) -> float:
    """``estimate(m)``, or infinite when rung ``m`` cannot be built (a ``SpecError``).

    E.g. strain gauges on ``rigid``.  Only a rung that cannot be built stops the walk this
    way; a solver or simulation failure on it is raised, as the other walks raise it.
    """
    try:
        return estimate(m)
    except SpecError:
        return math.inf
