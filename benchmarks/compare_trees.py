"""One study's runs under two source trees, alternated run by run: a change's per-run cost.

Run from a clone::

    git worktree add ../before OLD_COMMIT
    python benchmarks/compare_trees.py --study STUDY --tree ../before --tree .

One worker process per tree imports that tree's flexctrl (``PYTHONPATH`` = ``TREE/src``, or
``TREE`` for a tree of the earlier layout with ``flexctrl/`` at its top) and keeps its own
worker cache, as a study worker does. Every run of the study goes to both, in the study's
order, the two alternating from run to run so that the machine's load moves them together.
Printed: each tree's summed per-run wall time (``wall_time_s`` of
:func:`flexctrl.study.runner.execute_run`) per value of ``--by`` (default the ``controller``
column) and in all, the ratios to the first tree, and the largest relative difference of any
non-timing metric between the trees (with the run and metric where it is; below
:data:`flexctrl.bench.loop_overhead.FLOOR` in both trees the absolute difference counts, as
round-off). ``--exclude KEY=VALUE`` leaves runs out (e.g. ``controller=nmpc``). Both trees
read the same study file and must expand it into the same runs. Every process's first run
includes its imports.
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
try:
    from flexctrl.study.run_execution import execute_run
except ImportError:  # a tree of an earlier layout
    from flexctrl.study.runner import execute_run
try:
    from flexctrl.study.study_file import load_study
except ImportError:
    from flexctrl.study.spec import load_study
spec = load_study(sys.argv[1])
options = {
    "metrics": list(spec.metrics) if spec.metrics else None,
    "keep_trajectories": spec.keep_trajectories,
    "decimation": spec.decimation,
}
runs = [[run.run_id, {k: str(v) for k, v in run.coords}] for run in spec.runs]
print(json.dumps(runs), flush=True)
for line in sys.stdin:
    result = execute_run(spec.executor, spec.runs[int(line)].settings, options)
    record = {k: result[k] for k in ("status", "metrics")}
    print(json.dumps(dict(record, wall=result["wall_time_s"])), flush=True)
"""


def import_root(tree: Path) -> Path:
    """The folder that holds ``tree``'s package: ``src/`` or, in the earlier layout, the tree."""
    for root in (tree / "src", tree):
        if (root / "flexctrl" / "__init__.py").is_file():
            return root
    raise ValueError(
        f"--tree {str(tree)!r} is not a flexctrl checkout; allowed: a folder holding "
        "src/flexctrl/__init__.py or flexctrl/__init__.py"
    )


def _start(tree: Path, study: Path) -> tuple[subprocess.Popen, list]:
    """A worker on ``tree`` and the study's runs as it reads them (``[run_id, {column:
    value}]``)."""
    env = dict(os.environ, PYTHONPATH=str(import_root(tree)))
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
        f"compare_trees: {Path(result['study']).name}, {result['runs']} runs alternated between "
        f"{len(trees)} trees (load average {result['load_average_1min']}); summed run wall (s) "
        f"by {result['by']}"
    ]
    for group in result["summed_run_wall_s"][0]:
        values = " -> ".join(f"{w[group]:.2f}" for w in result["summed_run_wall_s"])
        lines.append(f"  {group:12s} {values}   ({result['ratio_to_first'][-1][group]:.2f}x)")
    lines.append(
        f"  {'all':12s} {' -> '.join(f'{t:.2f}' for t in result['total_s'])}   "
        f"({result['ratio_to_first'][-1]['total']:.2f}x)"
    )
    lines.append(
        "  largest relative metric difference first/last tree: "
        f"{result['max_metric_relative_difference']:.2g}"
        + (
            f" ({result['where']['metric']} of run {result['where']['run_id']})"
            if result["where"]
            else ""
        )
    )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """The command line (see the module docstring); exit status 2 on bad arguments."""
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--study", required=True, help="the study file both trees run")
    parser.add_argument("--tree", action="append", required=True, help="a checkout (twice)")
    parser.add_argument("--by", default="controller", help="column to sum the wall time by")
    parser.add_argument("--exclude", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if len(args.tree) != 2:
        parser.error(f"--tree given {len(args.tree)} times; allowed: exactly two --tree DIR")
    bad = [item for item in args.exclude if "=" not in item]
    if bad:
        parser.error(
            f"--exclude {bad[0]!r}; allowed: KEY=VALUE (a grid column and one of its values)"
        )
    try:
        for tree in args.tree:
            import_root(Path(tree).resolve())
    except ValueError as exc:
        parser.error(str(exc))
    result = bench_runs(args.study, args.tree, by=args.by, exclude=args.exclude)
    print(json.dumps(result, indent=2) if args.json else format_runs(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
