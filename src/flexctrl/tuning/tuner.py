"""The tuning loop: an optimiser proposing candidates, the scenarios judging them, the records kept.

Output folder::

    DIR/runs/<id>.json      every closed-loop run (the study store: kept, so a killed
                            tuning resumes)
    DIR/evaluations.jsonl   every candidate judged (rewritten whole after each batch)
    DIR/tuning.json         the outcome: initial_objective, best_objective, evaluations,
                            best_parameters, per_scenario (before and after), the settings,
                            timings
    DIR/controller.toml     the controller file with the best values, a comment naming the
                            tuning
    DIR/report.md           convergence plot (DIR/figures/convergence.png) and the
                            before/after table

Number 0 is the controller file as shipped (the "before"); the optimiser starts from the
file's values clipped to the bounds.
"""

from __future__ import annotations

import json
import math
import sys
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.errors import FlexctrlError, SpecError, keyword_checked
from flexctrl.spec.tuning import TuningSpec, load_tuning
from flexctrl.study.runner import make_backend
from flexctrl.study.store import ResultStore, atomic_write
from flexctrl.tuning.controller_file import write_controller
from flexctrl.tuning.evaluate import Evaluation, Evaluator
from flexctrl.tuning.optimizers import BudgetSpent, minimize
from flexctrl.tuning.scenarios import scenario_study


@dataclass
class TuningResult:
    """What :func:`tune` produced.

    Attributes
    ----------
    spec : TuningSpec
    initial : Evaluation
        The controller file as shipped.
    best : Evaluation or None
        The best feasible candidate (None when no candidate was feasible).
    evaluations : list of Evaluation
        Every candidate, in order.
    directory : Path
    wall_time_s : float
        This call's wall time (s).
    runs_made, runs_reused : int
        Closed-loop runs made by this call, and found in the store.
    """

    spec: TuningSpec
    initial: Evaluation
    best: Evaluation | None
    evaluations: list[Evaluation]
    directory: Path
    wall_time_s: float
    runs_made: int = 0
    runs_reused: int = 0
    files: list[Path] = field(default_factory=list)

    @property
    def summary(self) -> dict[str, Any]:
        """The content of ``tuning.json``."""
        best = self.best
        return {
            "tuning": self.spec.settings(),
            "initial_objective": _finite(self.initial.objective),
            "best_objective": None if best is None else _finite(best.objective),
            "initial_feasible": self.initial.feasible,
            "evaluations": len(self.evaluations) - 1,
            "feasible_evaluations": sum(e.feasible for e in self.evaluations[1:]),
            "best_number": None if best is None else best.number,
            "best_parameters": None if best is None else dict(best.values),
            "initial_parameters": {p.key: p.initial for p in self.spec.parameters},
            "per_scenario": [
                {
                    "coords": before["coords"],
                    "before": _scenario_figures(before),
                    "after": None if best is None else _scenario_figures(after),
                }
                for before, after in zip(self.initial.scenarios, (best or self.initial).scenarios)
            ],
            "wall_time_s": self.wall_time_s,
            "runs_made": self.runs_made,
            "runs_reused": self.runs_reused,
        }


@keyword_checked
def tune(
    tuning: str | Path | TuningSpec,
    out: str | Path,
    *,
    overrides: Iterable[str] = (),
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    progress: bool = True,
    stream=None,
) -> TuningResult:
    """Tune a controller file over closed-loop scenarios.

    :mod:`flexctrl.tuning.tuner` lists the files written.

    Parameters
    ----------
    tuning : str, Path or TuningSpec
        A tuning file (``studies/tune_lqr.toml``) or its validated description.
    out : str or Path
        The output folder; a folder holding this tuning's runs is resumed (its runs are
        reused, the optimiser replays to where it stopped).
    overrides : iterable of str
        ``KEY=VALUE`` strings for the tuning file (``optimizer.evaluations=10``).
    workers : int, optional
        Local pool size (default: the usable CPUs; 0: in this process).
    scheduler, client
        A Dask scheduler address or client instead of the local pool.
    progress : bool
        One line per batch on ``stream``.
    stream : file, optional
        Where the progress lines go (default stderr).

    Returns
    -------
    TuningResult

    Raises
    ------
    SpecError
        For a bad tuning file, before any run (parameter keys, bounds, scenarios, metric).
    FlexctrlError
        When no candidate, the shipped file included, is feasible (the files are still written).
    """
    started = time.perf_counter()
    spec = tuning if isinstance(tuning, TuningSpec) else load_tuning(tuning, overrides)
    study = scenario_study(spec)
    out = Path(out)
    stream = sys.stderr if stream is None else stream
    store = ResultStore(out)
    backend = make_backend(workers, scheduler, client)
    with store:
        _check_folder(out, spec)
        backend.start()
        try:
            evaluator = Evaluator(spec, study, store, backend)
            evaluations = [evaluator.evaluate([{}], 0)[0]]
            _log(stream, progress, spec, evaluations, evaluator, started)
            _search(spec, evaluator, evaluations, out, stream, progress, started)
        finally:
            backend.close()
        feasible = [e for e in evaluations[1:] if e.feasible]
        best = min(feasible, key=lambda e: e.score) if feasible else None
        if evaluations[0].feasible and (best is None or evaluations[0].score <= best.score):
            best = evaluations[0]  # nothing found beats the file as shipped
        result = TuningResult(
            spec,
            evaluations[0],
            best,
            evaluations,
            out,
            time.perf_counter() - started,
            evaluator.runs_made,
            evaluator.runs_reused,
        )
        _write(result)
    if best is None:
        raise FlexctrlError(
            f"no feasible candidate in {len(evaluations) - 1} evaluations of '{spec.name}' "
            f"(see {out / 'report.md'}): widen the bounds, relax the constraints or raise the "
            "budget"
        )
    return result


def _search(
    spec: TuningSpec,
    evaluator: Evaluator,
    evaluations: list[Evaluation],
    out: Path,
    stream,
    progress: bool,
    started: float,
) -> None:
    params = spec.parameters
    lows = np.array([p.to_unit(p.low) for p in params])
    highs = np.array([p.to_unit(p.high) for p in params])
    start = np.array(
        [
            p.to_unit(
                p.initial
                if p.initial is not None
                else math.sqrt(p.low * p.high)
                if p.scale == "log"
                else 0.5 * (p.low + p.high)
            )
            for p in params
        ]
    )
    x0 = (start - lows) / (highs - lows)
    budget = spec.optimizer.evaluations

    def evaluate(points):
        points = list(points)
        remaining = budget - (len(evaluations) - 1)
        if remaining <= 0:
            raise BudgetSpent
        batch = [
            {
                p.key: p.from_unit(lo + float(z) * (hi - lo))
                for p, lo, hi, z in zip(params, lows, highs, point)
            }
            for point in points[:remaining]
        ]
        judged = evaluator.evaluate(batch, len(evaluations))
        evaluations.extend(judged)
        _save_evaluations(out, evaluations)
        _log(stream, progress, spec, evaluations, evaluator, started)
        # beyond the budget a generation's members are not run: they score worst, and the next call
        # stops
        return [e.score for e in judged] + [math.inf] * (len(points) - len(judged))

    minimize(
        spec.optimizer.method, evaluate, x0, budget, spec.optimizer.population, spec.optimizer.seed
    )


def _check_folder(out: Path, spec: TuningSpec) -> None:
    path = out / "tuning.json"
    if path.is_file():
        previous = json.loads(path.read_text()).get("tuning", {}).get("name")
        if previous != spec.name:
            raise SpecError(
                f"'{out}' holds the tuning '{previous}', not '{spec.name}'; choose another --out",
                key="--out",
            )


def _save_evaluations(out: Path, evaluations: list[Evaluation]) -> None:
    text = "".join(json.dumps(e.to_dict(), allow_nan=False) + "\n" for e in evaluations)
    atomic_write(out / "evaluations.jsonl", text.encode(), fsync=False)


def _log(
    stream,
    progress: bool,
    spec: TuningSpec,
    evaluations: list[Evaluation],
    evaluator: Evaluator,
    started: float,
) -> None:
    if not progress:
        return
    feasible = [e for e in evaluations[1:] if e.feasible]
    best = min((e.score for e in feasible), default=math.nan)
    print(
        f"{spec.name}: {len(evaluations) - 1}/{spec.optimizer.evaluations} candidates, "
        f"{len(feasible)} feasible, "
        f"best {spec.objective.statistic} {spec.objective.metric} {best:.4g}, runs made "
        f"{evaluator.runs_made}, "
        f"reused {evaluator.runs_reused}, {time.perf_counter() - started:.0f} s",
        file=stream,
        flush=True,
    )


def _write(result: TuningResult) -> None:
    from flexctrl.tuning.tuning_report import metric_unit, write_report

    out = result.directory
    out.mkdir(parents=True, exist_ok=True)
    _save_evaluations(out, result.evaluations)
    files = [out / "evaluations.jsonl"]
    if result.best is not None:
        spec = result.spec
        unit, factor = metric_unit(spec.objective.metric)
        header = (
            f"Tuned by `flexctrl tune {spec.source} --out {out}` from {spec.controller.name}: "
            f"{spec.objective.statistic} {spec.objective.metric} over "
            f"{len(result.initial.scenarios)} scenarios "
            f"{_fmt(factor * result.initial.objective)} -> "
            f"{_fmt(factor * result.best.objective)} {unit} "
            f"(candidate {result.best.number} of {len(result.evaluations) - 1}, "
            f"{spec.optimizer.method})."
        )
        integers = {p.key for p in spec.parameters if p.integer}
        values = {k: int(v) if k in integers else v for k, v in result.best.values.items()}
        files.append(write_controller(spec.controller, values, out / "controller.toml", header))
    atomic_write(
        out / "tuning.json", (json.dumps(result.summary, indent=2, allow_nan=False) + "\n").encode()
    )
    files.append(out / "tuning.json")
    files += write_report(result)
    result.files = files


def _fmt(value: float) -> str:
    return "n/a" if not math.isfinite(value) else f"{value:.4g}"


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _scenario_figures(scenario: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in scenario.items() if k not in ("coords", "run_id")}
