"""One candidate of a tuning: the controller file with the tuned keys set, run on every scenario and
judged.

A candidate's runs are study runs (the scenario's settings plus the candidate's
``controller.KEY=VALUE`` overrides), so their ids are hashes of everything that makes
them: a run already in the store is never run again, which is what makes a killed tuning
resume where it stopped and a replayed optimiser cost nothing.  Runs go through the
study backends (local pool or Dask) a whole batch of candidates at a time.

A candidate is *feasible* when every scenario ran, and, as the tuning's constraints ask,
was stable and settled (``stable = 1`` and ``settled_within_band = 1``), kept its torques
within the limits, had a linear closed-loop radius below the bound (wherever the controller
has a full-state gain) and solved in real time (``controller_time_p95`` below its sample
time).  The optimiser minimises
:attr:`Evaluation.score`: the objective for a feasible candidate, and for an infeasible one
:data:`PENALTY` times one plus its number of violated scenario constraints, so every
infeasible candidate ranks below every feasible one and fewer violations rank better.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flexctrl.spec.controller_reader import load_controller
from flexctrl.spec.tuning import TuningSpec
from flexctrl.study.plan import StudySpec
from flexctrl.study.store import ResultStore
from flexctrl.tuning.scenarios import candidate_overrides, candidate_runs

#: Score of an infeasible candidate per violation (far above any metric in SI units).
PENALTY = 1.0e6
_STATISTICS: dict[str, Callable[[Sequence[float]], Any]] = {
    "median": np.median,
    "max": np.max,
    "mean": np.mean,
}


@dataclass(frozen=True)
class Evaluation:
    """A judged candidate.

    Attributes
    ----------
    number : int
        Order of evaluation (0: the controller file as shipped, before tuning).
    values : dict
        Tuned key -> value, in the file's units (empty for the file as shipped).
    objective : float
        The objective's statistic over the scenarios (the metric's unit), NaN when a
        scenario produced no value.
    feasible : bool
    violations : tuple of str
        Why not, one line per broken constraint and scenario.
    scenarios : tuple of dict
        Per scenario: ``coords``, ``run_id``, ``status``, ``error`` and its metrics.
    """

    number: int
    values: dict[str, float]
    objective: float
    feasible: bool
    violations: tuple[str, ...] = ()
    scenarios: tuple[dict[str, Any], ...] = field(default=(), repr=False)

    @property
    def score(self) -> float:
        """What the optimiser minimises (see the module docstring)."""
        if self.feasible and math.isfinite(self.objective):
            return float(self.objective)
        return PENALTY * (1 + len(self.violations))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "number": self.number,
            "values": dict(self.values),
            "objective": self.objective if math.isfinite(self.objective) else None,
            "feasible": self.feasible,
            "score": self.score,
            "violations": list(self.violations),
            "scenarios": list(self.scenarios),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Evaluation:
        objective = data.get("objective")
        return cls(
            int(data["number"]),
            dict(data["values"]),
            math.nan if objective is None else float(objective),
            bool(data["feasible"]),
            tuple(data.get("violations", ())),
            tuple(data.get("scenarios", ())),
        )


def _stability_violations(where: str, m: dict) -> list[str]:
    """What the ``stable`` constraint objects to: an unstable run (diverged, or a linear
    closed-loop radius >= 1), or a stable one whose tip is not inside the band at the end."""
    if m.get("stable", 0) != 1:
        when = m.get("divergence_time")
        radius = m.get("closed_loop_radius")
        why = (
            f"diverged at {when:.4g} s"
            if isinstance(when, float) and math.isfinite(when)
            else f"linear closed-loop radius {radius:.6g} >= 1"
            if isinstance(radius, float)
            else "stable = 0"
        )
        return [f"{where}: unstable ({why})"]
    if m.get("settled_within_band", 1) != 1:
        return [
            f"{where}: stable but not settled within the band (final tip error "
            f"{m.get('final_tip_error', math.nan):.3g} m)"
        ]
    return []


#: Metrics kept per scenario in an evaluation's record.
_KEPT = (
    "tip_residual_rms",
    "tip_residual_peak",
    "settling_time",
    "peak_deflection",
    "stable",
    "settled_within_band",
    "divergence_time",
    "final_tip_error",
    "closed_loop_radius",
    "torque_limit_exceeded",
    "controller_time_p95",
    "controller_time_median",
    "peak_torque_1",
    "peak_torque_2",
    "peak_torque_3",
)


class Evaluator:
    """Runs and judges candidates of one tuning on one backend and one run store.

    Parameters
    ----------
    spec : TuningSpec
    study : StudySpec
        The scenario study (:func:`flexctrl.tuning.scenarios.scenario_study`).
    store : ResultStore
        Where every run's record is kept (opened by the caller).
    backend
        A study backend (``flexctrl.study.runner.make_backend``), started by the caller.
    on_run : callable, optional
        ``on_run(done, total)`` after every run that had to be made.
    """

    def __init__(
        self, spec: TuningSpec, study: StudySpec, store: ResultStore, backend, on_run=None
    ):
        self.spec, self.study, self.store, self.backend = spec, study, store, backend
        self.on_run = on_run
        self.runs_made = 0
        self.runs_reused = 0
        self._sample_times: dict[tuple[str, ...], float] = {}

    def evaluate(self, batch: Sequence[dict[str, float]], first_number: int) -> list[Evaluation]:
        """Judge every candidate of ``batch`` (tuned key -> value; ``{}`` is the file as
        shipped)."""
        overrides = [
            candidate_overrides(self.spec.parameters, values) if values else [] for values in batch
        ]
        runs_per = [candidate_runs(self.study, o) for o in overrides]
        todo, seen = [], set()
        for runs in runs_per:
            for run in runs:
                if run.run_id in seen:
                    continue
                seen.add(run.run_id)
                record = self.store.read_record(run.run_id)
                if record is not None and record.get("status") in ("ok", "failed"):
                    self.runs_reused += 1
                else:
                    todo.append(run)
        options = {"metrics": None, "keep_trajectories": False, "decimation": 1}
        for done, (run, result) in enumerate(
            self.backend.run(todo, self.study.executor, options), start=1
        ):
            self.store.save(run, result)
            self.runs_made += 1
            if self.on_run is not None:
                self.on_run(done, len(todo))
        return [
            self._judge(number, values, o, runs)
            for number, (values, o, runs) in enumerate(
                zip(batch, overrides, runs_per), start=first_number
            )
        ]

    def _sample_time(self, overrides: list[str]) -> float:
        key = tuple(overrides)
        if key not in self._sample_times:
            controller_overrides = [o[len("controller.") :] for o in overrides]
            self._sample_times[key] = float(
                load_controller(self.spec.controller, controller_overrides).sample_time
            )
        return self._sample_times[key]

    def _judge(
        self, number: int, values: dict[str, float], overrides: list[str], runs
    ) -> Evaluation:
        c = self.spec.constraints
        metric = self.spec.objective.metric
        violations: list[str] = []
        scenarios = []
        samples = []
        for run in runs:
            record = self.store.read_record(run.run_id) or {
                "status": "failed",
                "error": "no record",
                "metrics": {},
            }
            coords = dict(run.coords)
            where = ", ".join(f"{k} = {v}" for k, v in coords.items()) or "the scenario"
            m = record.get("metrics") or {}
            scenarios.append(
                {
                    "coords": coords,
                    "run_id": run.run_id,
                    "status": record["status"],
                    "error": record.get("error", ""),
                    **{k: m[k] for k in _KEPT if k in m},
                }
            )
            if record["status"] != "ok":
                violations.append(f"{where}: the run failed ({record.get('error', '')})")
                continue
            value = m.get(metric)
            if isinstance(value, (int, float)) and math.isfinite(value):
                samples.append(float(value))
            elif metric in m:  # recorded empty, the reason in the run's error cell
                violations.append(f"{where}: no {metric} ({record.get('error') or 'empty'})")
            else:
                violations.append(f"{where}: no metric '{metric}'")
            if c.stable:
                violations += _stability_violations(where, m)
            if c.torque_limits and m.get("torque_limit_exceeded", 0):
                violations.append(f"{where}: a torque beyond its joint's limit")
            radius = m.get("closed_loop_radius")
            if (
                c.closed_loop_radius is not None
                and radius is not None
                and not radius < c.closed_loop_radius
            ):
                violations.append(
                    f"{where}: linear closed-loop radius {radius:.6g} >= {c.closed_loop_radius:g}"
                )
            if c.real_time and m.get("controller_time_p95", 0.0) >= self._sample_time(overrides):
                violations.append(
                    f"{where}: controller p95 {1e3 * m['controller_time_p95']:.3g} ms not below "
                    "the "
                    f"sample time {1e3 * self._sample_time(overrides):.3g} ms"
                )
        objective = (
            float(_STATISTICS[self.spec.objective.statistic](samples))
            if len(samples) == len(runs)
            else math.nan
        )
        return Evaluation(
            number, dict(values), objective, not violations, tuple(violations), tuple(scenarios)
        )
