"""The linear estimates' candidate rung: where the estimate-first walk starts certifying.

A closed loop's rungs are first run on their linearised plants (cheap when the controller's
law is one compiled call); the lowest rung those estimates cannot exclude is the candidate
the nonlinear runs then certify (:mod:`flexctrl.fidelity.walk`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from flexctrl.errors import FlexctrlError
from flexctrl.fidelity.records import RunRecord
from flexctrl.fidelity.rungs import rung_name, tip_distance

#: Bound assumed on the linear estimate's error either way: a rung whose linear estimate exceeds
# : ``LINEAR_FACTOR`` times the tolerance is not certified (docs/explanation/automatic-fidelity.md
# gives the ratios
#: measured on the quickstart's loops; tests/scenes/test_auto_linear.py checks a small case).
LINEAR_FACTOR = 3.0


def linear_candidate(
    linear_rung: Callable[[int], RunRecord],
    *,
    tol: float,
    low: int,
    top: int,
    ref_n: int,
    safety: float,
    factor: float = LINEAR_FACTOR,
) -> tuple[int | None, dict[str, Any]]:
    """The lowest rung whose linear estimate is within ``factor`` of ``tol``, and the evidence.

    The linear estimate of rung ``m`` is the walk's formula (``safety`` times the largest
    tip distance to rungs ``m + 1`` and ``m + 2``, up to ``ref_n``) on the linear runs
    ``linear_rung(m)``.  Rungs are estimated from the top down while their estimate is
    at most ``factor * tol``; the lowest of that unbroken run of rungs is the candidate.
    When ``top`` is excluded, the rungs below are estimated until one is not (the
    candidate is then the lowest of its unbroken run), or None when every rung is
    excluded (unreachable, as predicted, without a nonlinear run).  A rung that cannot
    be built (``FlexctrlError``, e.g. strain gauges on ``rigid``) is excluded.
    """
    runs: dict[int, RunRecord | str] = {}

    def run(m: int) -> RunRecord | str:
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
                distances = [tip_distance(p, here).max for p in pair if not isinstance(p, str)]
                estimates[m] = safety * max(distances)
        return estimates[m]

    n = None
    for m in range(top, low - 1, -1):
        if estimate(m) <= factor * tol:
            n = m
        elif n is not None:
            break
    return n, _linear_evidence(runs, estimates, factor, tol, n)


def _linear_evidence(runs, estimates, factor: float, tol: float, n: int | None) -> dict[str, Any]:
    """The linear estimates' evidence: every rung's run (or why it is unavailable) and estimate."""
    rungs = []
    for m in sorted(runs):
        record = runs[m]
        item: dict[str, Any] = {"fidelity": rung_name(m)}
        if isinstance(record, str):
            item["unavailable"] = record
        else:
            item.update(record.facts())
        if m in estimates:
            item["estimated_error_m"] = estimates[m]
        rungs.append(item)
    return {
        "factor": factor,
        "threshold_m": factor * tol,
        "candidate": None if n is None else rung_name(n),
        "rungs": rungs,
        "wall_time_s": sum(
            r.wall_time_s + r.build_time_s for r in runs.values() if not isinstance(r, str)
        ),
    }
