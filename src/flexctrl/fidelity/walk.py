"""The walk of the fidelity ladder and its judgement against the reference.

:func:`walk_and_judge` is steps 2 and 3 of the method of :mod:`flexctrl.fidelity.ladder`,
shared by arm and closed-loop scenes: it runs rungs through the callables it is given, walks
the ladder (from the bandwidth rule's start, from the top, or from the linear estimate's
candidate, :func:`linear_candidate`) and judges the choice against the reference model.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

from flexctrl.errors import FlexctrlError, SimulationError, SpecError
from flexctrl.fidelity.records import (
    FidelityChoice,
    RunRecord,
    ToleranceUnreachable,
    rung_name,
    tip_distance,
)
from flexctrl.spec.fidelity import FIDELITY_CHECKS, FIDELITY_WALKS, parse_fidelity

# -- the method -------------------------------------------------------------------------------
METHOD = (
    "lowest rung whose safety * (largest tip distance to the next two rungs, up to the reference "
    "model) <= "
    "tolerance; walk from the bandwidth rule's start"
)


# : Bound assumed on the linear estimate's error either way: a rung whose linear estimate exceeds
# ``LINEAR_FACTOR``
# : times the tolerance is not certified (measured on the quickstart's loops: nonlinear / linear
# estimate 0.43-1.17,
#: docs/auto_fidelity.md; tests/test_fidelity_estimate.py checks a small case).
LINEAR_FACTOR = 3.0
#: The walks of the closed-loop chooser (:data:`flexctrl.spec.fidelity.FIDELITY_WALKS`).
WALKS = FIDELITY_WALKS
METHOD_ESTIMATE = (
    "linear estimate of every rung (the loop on each rung's linearised plant at its own RK4 "
    "step), then "
    "the lowest rung it cannot exclude certified by nonlinear runs: lowest rung whose safety * "
    "(largest "
    "tip distance to the next two rungs, up to the reference model) <= tolerance, walking up"
)


METHOD_FROM_TOP = (
    "nonlinear runs from the top rung down (the controller steps in Python: a linear run would "
    "cost as much "
    "as a nonlinear one): the lowest rung of the unbroken run from the top whose safety * "
    "(largest tip "
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
    """The lowest rung whose linear estimate is within ``factor`` of the tolerance, and the
    evidence.

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
    """``estimate(m)``, infinite when rung ``m`` cannot be built (``SpecError``, e.g. strain gauges
    on ``rigid``).

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
    if from_top and linear is None:
        raise ValueError("from_top needs the linear runs for the reference's step check")
    walk = _Walk(name, tol, low, top, reference, safety, rule, run_rung, runs, checks)
    extra = dict(extra or {})
    linear_evidence = None
    if from_top:
        n = walk.down_from(top)
    elif linear is None:
        n = walk.ladder_from(start)
    else:
        n, linear_evidence = linear_candidate(
            linear[0], tol=tol, low=low, top=top, ref_n=walk.ref_n, safety=safety, factor=factor
        )
        extra["linear_estimate"] = linear_evidence
        if n is None:
            raise walk.predicted_unreachable(linear_evidence, factor, extra)
        n = walk.up_from(n)
    method = _method(linear, from_top)
    if walk.estimate(n) > tol:
        raise walk.measured_unreachable(method, from_top, extra)
    reference_run, finest, convergence = walk.reference_run(
        linear, linear_evidence, run_reference, reference_dt
    )
    return walk.choice(n, method, reference_run, finest, convergence, linear is None, extra)


class _Walk:
    """The runs and estimates of one walk of the ladder (:func:`walk_and_judge`'s steps)."""

    def __init__(self, name, tol, low, top, reference, safety, rule, run_rung, runs, checks):
        self.name, self.tol, self.low, self.top, self.reference = name, tol, low, top, reference
        self.safety, self.rule, self.run_rung, self.checks = safety, rule, run_rung, checks
        self.full = checks == "full"
        self.ref_n = parse_fidelity(reference).count
        self.runs: dict[int, RunRecord] = dict(runs or {})
        self.distances: dict[int, list[float]] = {}

    def run(self, m: int) -> RunRecord:
        """Rung ``m``'s nonlinear run (made once)."""
        if m not in self.runs:
            self.runs[m] = self.run_rung(m)
        return self.runs[m]

    def estimate(self, m: int) -> float:
        """``safety`` times rung ``m``'s largest tip distance to the (two) rungs above."""
        if m not in self.distances:
            above = range(m + 1, min(m + 2, self.ref_n) + 1)
            self.distances[m] = [tip_distance(self.run(k), self.run(m)).max for k in above]
        return self.safety * max(self.distances[m])

    def down_from(self, n: int) -> int:
        """From ``n`` down while the rung below meets the tolerance (the walk from the top)."""
        while (
            self.full
            and n - 1 >= self.low
            and self.estimate(n) <= self.tol
            and _buildable_estimate(self.estimate, n - 1) <= self.tol
        ):
            n -= 1
        return n

    def ladder_from(self, n: int) -> int:
        """The ladder walk: down from ``n`` while the rungs meet the tolerance, else up."""
        if self.estimate(n) <= self.tol:
            while self.full and n - 1 >= self.low and self.estimate(n - 1) <= self.tol:
                n -= 1
            return n
        return self.up_from(n)

    def up_from(self, n: int) -> int:
        """From ``n`` up while the rung does not meet the tolerance (at most ``top``)."""
        while n < self.top and self.estimate(n) > self.tol:
            n += 1
        return n

    def _evidence(self, method: str, extra: dict) -> dict[str, Any]:
        return {
            "method": method,
            "checks": self.checks,
            "safety": self.safety,
            "ladder": [rung_name(m) for m in range(self.low, self.top + 1)],
            "bandwidth_rule": self.rule,
            "scene": self.name,
            **extra,
        }

    def predicted_unreachable(self, linear_evidence, factor, extra) -> ToleranceUnreachable:
        """No rung within ``factor`` of the tolerance by the linear estimate: no nonlinear run."""
        best = min(
            linear_evidence["rungs"], key=lambda item: item.get("estimated_error_m", math.inf)
        )
        error = best.get("estimated_error_m", math.inf)
        evidence = self._evidence(METHOD_ESTIMATE, extra)
        evidence.pop("ladder")
        evidence.update(
            {
                "reference": None,
                "candidates": [],
                "predicted": True,
                "best": {
                    "rung": best["fidelity"],
                    "estimated_error_m": error,
                    "from": "linear estimate",
                },
            }
        )
        return ToleranceUnreachable(
            f"no rung up to amm:{self.top} meets the tolerance {self.tol:.3g} m on scene "
            f"'{self.name}', predicted by the linear estimate: its best is {error:.3g} m "
            f"({best['fidelity']}), above {factor:g} x the tolerance (the bound assumed on its "
            "error), so no nonlinear run was made; allowed: a tolerance >= "
            f"{error / factor:.3g} m, a higher top rung, or fidelity_walk = 'ladder'",
            evidence,
        )

    def measured_unreachable(self, method, from_top: bool, extra) -> ToleranceUnreachable:
        """No rung meets the tolerance: no reference is needed to judge a choice."""
        best = min(self.distances, key=lambda m: max(self.distances[m]))
        error = self.safety * max(self.distances[best])
        evidence = self._evidence(method, extra)
        evidence.update(
            {
                "candidates": [self._facts(m) for m in sorted(self.runs)],
                "reference": None,
                "best": {"rung": rung_name(best), "estimated_error_m": error},
            }
        )
        tol, top = self.tol, self.top
        if from_top:
            return ToleranceUnreachable(
                f"the top rung amm:{top} does not meet the tolerance {tol:.3g} m on scene "
                f"'{self.name}': its estimate is {error:.3g} m ({self.safety:g} x its largest "
                "distance to the rungs above); the walk from the top tries no rung below a top "
                f"that fails; allowed: a tolerance >= {error:.3g} m, a higher top rung, or "
                "fidelity_walk = 'ladder' (it tries the rungs below)",
                evidence,
            )
        return ToleranceUnreachable(
            f"no rung up to amm:{top} meets the tolerance {tol:.3g} m on scene '{self.name}': "
            f"the best estimate is {error:.3g} m ({rung_name(best)}, {self.safety:g} x its "
            f"largest distance to the rungs above); allowed: a tolerance >= {error:.3g} m, or a "
            "higher top rung",
            evidence,
        )

    def _facts(self, m: int) -> dict[str, Any]:
        return {**self.runs[m].facts(), **_estimates(m, self.distances, self.safety)}

    def reference_run(self, linear, linear_evidence, run_reference, reference_dt):
        """The reference run, the finest rung's own run (or None) and the convergence evidence."""
        full, ref_n = self.full, self.ref_n
        # the reference model as a user would run it (its own step): the "always finest" cost;
        # in the ladder walk only evidence (its cost ratio), so not run for it with
        # checks = "tolerance"
        finest = self.run(ref_n) if full or linear is not None or ref_n in self.runs else None
        if linear is None:
            ref_dt = reference_dt
            ref_run = run_reference(ref_dt)
            half = run_reference(ref_dt / 2) if full else ref_run
        else:  # the estimate-first walk: the reference at its own step, its step error linear
            ref_dt, ref_run, half = finest.dt, finest, finest
        if ref_run.diverged_at is not None or half.diverged_at is not None:
            raise SimulationError(
                f"the reference {self.reference} (rk4, dt = {ref_dt:.3g} s) diverged at "
                f"{ref_run.diverged_at or half.diverged_at:.4g} s on scene '{self.name}': "
                "nothing to judge the choice against"
            )
        below = self.run(ref_n - 1) if full or ref_n - 1 in self.runs else None
        model_check = 0.0 if below is None else tip_distance(ref_run, below).max
        step_check, convergence = self._step_check(linear, linear_evidence, ref_run, half)
        convergence.update(
            {
                "rung_below_m": None if below is None else model_check,
                "rung_below": rung_name(ref_n - 1),
            }
        )
        if max(step_check, model_check) > 0.5 * self.tol:
            self._warn_unconverged(linear, ref_dt, step_check, model_check)
        return ref_run, finest, convergence

    def _step_check(self, linear, linear_evidence, ref_run, half) -> tuple[float, dict]:
        """How far the reference moves with its step: halved, or without integrator error."""
        if not self.full:
            return 0.0, {"step_check": "not made (fidelity_checks = 'tolerance')"}
        if linear is None:
            step_check = tip_distance(half, ref_run).max
            return step_check, {"step_halving_m": step_check, "half_step_run": half.facts()}
        exact = linear[1]()
        step_check = tip_distance(exact, linear[0](self.ref_n)).max
        convergence = {
            "step_error_linear_m": step_check,
            "step_check": "linear estimate: the reference model's linear loop at its own RK4 "
            "step against the same loop without integrator error (zero-order hold)",
        }
        if linear_evidence is not None:
            linear_evidence["reference_exact"] = exact.facts()
        else:
            convergence["reference_exact"] = exact.facts()
        return step_check, convergence

    def _warn_unconverged(self, linear, ref_dt, step_check, model_check) -> None:
        how = "half its step" if linear is None else "no integrator error (linear estimate)"
        moves = f"moves by {step_check:.3g} m with {how} and " if self.full else ""
        warnings.warn(
            f"the reference {self.reference} (rk4, dt = {ref_dt:.3g} s) {moves}differs by "
            f"{model_check:.3g} m from {rung_name(self.ref_n - 1)}: above half the tolerance "
            f"{self.tol:.3g} m, so it may not be converged enough to judge the choice",
            stacklevel=4,
        )

    def choice(self, n, method, ref_run, finest, convergence, ladder: bool, extra):
        """The choice of rung ``n`` with its evidence against the reference."""

        def ratio(a: RunRecord, b: RunRecord) -> float:
            return a.wall_time_s / b.wall_time_s if b.wall_time_s > 0 else math.inf

        rungs = []
        for m in sorted(self.runs):
            err = tip_distance(ref_run, self.runs[m])
            item = {
                "reference_error_max_m": err.max,
                "reference_error_rms_m": err.rms,
                "cost_ratio": ratio(self.runs[m], ref_run),
            }
            rungs.append(
                {**self.runs[m].facts(), **item, **_estimates(m, self.distances, self.safety)}
            )
        role = (
            "the reference model at omega_max * dt <= reference_omega_dt"
            if ladder
            else "the reference model at its own RK4 step (fidelity_walk = 'estimate')"
        )
        evidence = self._evidence(method, {})
        evidence.update(
            {
                "reference": {**ref_run.facts(), "convergence": convergence, "role": role},
                "candidates": rungs,
                **extra,
            }
        )
        chosen = self.run(n)
        err = tip_distance(ref_run, chosen)
        evidence["cost_ratio_vs_finest"] = None if finest is None else ratio(chosen, finest)
        evidence["finest"] = rung_name(self.ref_n)
        return FidelityChoice(
            choice=parse_fidelity(rung_name(n)),
            tolerance=self.tol,
            estimated_error=self.estimate(n),
            reference_error=err.max,
            reference_error_rms=err.rms,
            cost_ratio=ratio(chosen, ref_run),
            integrator=chosen.integrator,
            dt=chosen.dt,
            evidence=evidence,
        )
