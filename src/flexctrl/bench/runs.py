"""One study's runs under two source trees, alternated run by run: a code change's per-run cost, measured side by side.

``flexctrl bench runs --study FILE --tree OLD --tree NEW`` starts one worker process per
source tree (``PYTHONPATH`` = the tree; each keeps its own worker cache, as a study
worker does) and sends every run of the study, in the study's order, to both, the order
of the two alternating from run to run, so the machine's load moves them together.
Reported: each tree's summed per-run wall time (:func:`flexctrl.study.runner.execute_run`'s
``wall_time_s``) per value of ``--by`` (default the ``controller`` column) and in all, the
ratios to the first tree, and the largest relative difference of any non-timing metric
between the trees (with the run and metric where it is, and the largest per metric; for metrics below
:data:`~flexctrl.bench.loop_overhead.FLOOR` in both trees, round-off, the absolute difference, as
:func:`~flexctrl.bench.loop_overhead.metric_differences` compares them).  ``--exclude KEY=VALUE`` leaves
runs out (e.g. ``controller=nmpc``).  Both trees read the same study file (and the scene,
model and controller files it names); they must expand it into the same runs.  Every
process's first run includes its imports.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from flexctrl.bench.loop_overhead import FLOOR, TIMING_METRICS

_WORKER = """
import json, sys
from flexctrl.study.runner import execute_run
from flexctrl.study.study_file import load_study
spec = load_study(sys.argv[1])
options = {"metrics": list(spec.metrics) if spec.metrics else None, "keep_trajectories": spec.keep_trajectories,
           "decimation": spec.decimation}
print(json.dumps([[run.run_id, {k: str(v) for k, v in run.coords}] for run in spec.runs]), flush=True)
for line in sys.stdin:
    result = execute_run(spec.executor, spec.runs[int(line)].settings, options)
    print(json.dumps({"wall": result["wall_time_s"], "status": result["status"], "metrics": result["metrics"]}),
          flush=True)
"""


def _start(tree: Path, study: Path) -> tuple[subprocess.Popen, list]:
    """A worker on ``tree`` and the study's runs as it reads them (``[run_id, {column: value}]``)."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    proc = subprocess.Popen(
        [sys.executable, "-c", _WORKER, str(study)],
        cwd=tree,
        env=env,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    line = proc.stdout.readline()
    if not line:
        raise RuntimeError(f"the worker on {tree} did not start (exit code {proc.wait()})")
    return proc, json.loads(line)


def _ask(proc: subprocess.Popen, index: int) -> dict[str, Any]:
    proc.stdin.write(f"{index}\n")
    proc.stdin.flush()
    return json.loads(proc.stdout.readline())


def bench_runs(
    study: str | Path,
    trees: Sequence[str | Path],
    *,
    by: str = "controller",
    exclude: Sequence[str] = (),
) -> dict[str, Any]:
    """Measure what the module docstring describes; a JSON-ready dict."""
    study = Path(study).resolve()
    trees = [Path(t).resolve() for t in trees]
    started = [_start(tree, study) for tree in trees]
    procs, listed = [p for p, _ in started], started[0][1]
    if any(other != listed for _, other in started[1:]):
        raise RuntimeError(
            f"the trees expand {study} into different runs; the comparison needs the same runs"
        )
    drop = [tuple(item.split("=", 1)) for item in exclude]
    runs = [
        i for i, (_, coords) in enumerate(listed) if not any(coords.get(k) == v for k, v in drop)
    ]
    walls: list[dict[str, float]] = [defaultdict(float) for _ in trees]
    worst = (0.0, None)
    by_metric: dict[str, float] = {}
    try:
        for j, index in enumerate(runs):
            order = list(range(len(trees)))[:: 1 if j % 2 == 0 else -1]
            results = {k: _ask(procs[k], index) for k in order}
            group = listed[index][1].get(by, "")
            for k in range(len(trees)):
                walls[k][group] += results[k]["wall"]
            for name, value in results[0]["metrics"].items():
                other = results[len(trees) - 1]["metrics"].get(name)
                if name in TIMING_METRICS or other is None or other == value:
                    continue
                scale = max(abs(value), abs(other))
                d = abs(value - other) / (
                    scale if scale > FLOOR else 1.0
                )  # round-off below FLOOR: absolute
                if d > worst[0]:
                    worst = (
                        d,
                        {"run_id": listed[index][0], "metric": name, "values": [value, other]},
                    )
                by_metric[name] = max(by_metric.get(name, 0.0), d)
    finally:
        for proc in procs:
            proc.stdin.close()
            proc.wait()
    totals = [sum(w.values()) for w in walls]
    return {
        "study": str(study),
        "trees": [str(t) for t in trees],
        "runs": len(runs),
        "by": by,
        "summed_run_wall_s": [dict(w) for w in walls],
        "total_s": totals,
        "ratio_to_first": [
            {g: walls[0][g] / w[g] for g in w} | {"total": totals[0] / t}
            for w, t in zip(walls, totals)
        ],
        "max_metric_relative_difference": worst[0],
        "where": worst[1],
        "metric_differences": dict(sorted(by_metric.items(), key=lambda item: -item[1])),
        "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
    }


def format_runs(result: dict[str, Any]) -> str:
    """Human-readable lines of :func:`bench_runs`."""
    trees = result["trees"]
    lines = [
        f"flexctrl bench runs: {Path(result['study']).name}, {result['runs']} runs alternated between "
        f"{len(trees)} trees (load average {result['load_average_1min']}); summed run wall (s) by {result['by']}"
    ]
    for group in result["summed_run_wall_s"][0]:
        values = " -> ".join(f"{w[group]:.2f}" for w in result["summed_run_wall_s"])
        lines.append(f"  {group:12s} {values}   ({result['ratio_to_first'][-1][group]:.2f}x)")
    lines.append(
        f"  {'all':12s} {' -> '.join(f'{t:.2f}' for t in result['total_s'])}   "
        f"({result['ratio_to_first'][-1]['total']:.2f}x)"
    )
    lines.append(
        f"  largest relative metric difference first/last tree: {result['max_metric_relative_difference']:.2g}"
        + (
            f" ({result['where']['metric']} of run {result['where']['run_id']})"
            if result["where"]
            else ""
        )
    )
    return "\n".join(lines)
