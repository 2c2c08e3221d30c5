"""Runs per minute of a study on a localhost Dask cluster of 1, 2, ... workers.

``python benchmarks/dask_throughput.py STUDY [--workers 1 2] [--set KEY=VALUE] [--json]``
starts a real cluster (:class:`flexctrl.study.dask_cluster.LocalhostCluster`: ``dask
scheduler`` and ``dask worker`` processes) per size and runs the whole study on it.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

from flexctrl.errors import FlexctrlError
from flexctrl.study.blas_threads import parse_blas_threads
from flexctrl.study.dask_cluster import LocalhostCluster


def throughput(
    study: str | os.PathLike,
    worker_counts: Sequence[int] = (1, 2),
    overrides: Sequence[str] = (),
    blas_threads: int | str = "auto",
) -> dict:
    """Runs per minute of ``study`` on a :class:`LocalhostCluster` of each size in
    ``worker_counts``.

    Every size runs the whole study into a fresh folder with fresh workers (the compiled
    code cache on disk is shared, as on a cluster with a shared file system); the result
    has per size ``runs``, ``ok``, ``elapsed_s``, ``runs_per_minute`` and the ``speedup``
    against the first size, plus the load average before and after.  ``blas_threads`` is
    :class:`LocalhostCluster`'s.
    """
    from flexctrl.study import load_study, run_study

    spec = load_study(study, overrides=list(overrides))
    result: dict = {
        "study": str(study),
        "overrides": list(overrides),
        "cpu_count": os.cpu_count(),
        "blas_threads": blas_threads,
        "load_average_before": list(os.getloadavg()),
        "sizes": {},
    }
    for n in worker_counts:
        with (
            tempfile.TemporaryDirectory(prefix="flexctrl-dask-out-") as out,
            LocalhostCluster(n, blas_threads=blas_threads) as cluster,
        ):
            start = time.perf_counter()
            run = run_study(
                spec, Path(out) / "study", scheduler=cluster.address, progress="none", report=False
            )
            elapsed = time.perf_counter() - start
        runs = sum(run.counts.get(k, 0) for k in ("ok", "failed"))
        result["sizes"][str(n)] = {
            "workers": n,
            "blas_threads_per_worker": cluster.blas_threads,
            "runs": runs,
            "ok": run.counts.get("ok", 0),
            "elapsed_s": elapsed,
            "runs_per_minute": 60.0 * runs / elapsed,
            "backend": run.backend,
        }
    first = result["sizes"][str(worker_counts[0])]["runs_per_minute"]
    for size in result["sizes"].values():
        size["speedup"] = size["runs_per_minute"] / first
    result["load_average_after"] = list(os.getloadavg())
    return result


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python benchmarks/dask_throughput.py",
        description="runs per minute of a study on a localhost Dask cluster of 1, 2, ... workers",
    )
    parser.add_argument("study")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="study-file override (repeatable)",
    )
    parser.add_argument(
        "--blas-threads",
        default="auto",
        metavar="N",
        help="BLAS threads per worker: auto (CPUs // workers, the default) or a whole number",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    try:
        blas_threads = parse_blas_threads(args.blas_threads)
    except FlexctrlError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    result = throughput(args.study, args.workers, args.set, blas_threads)
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        print(
            f"{args.study}: load {result['load_average_before'][0]:.2f} -> "
            f"{result['load_average_after'][0]:.2f} "
            f"on {result['cpu_count']} CPUs"
        )
        for size in result["sizes"].values():
            threads = size["blas_threads_per_worker"] or "default"
            print(
                f"  {size['workers']} worker(s), {threads} BLAS thread(s) each: {size['runs']} "
                f"runs ({size['ok']} ok) "
                f"in {size['elapsed_s']:.1f} s = {size['runs_per_minute']:.1f} runs/min, "
                f"speed-up {size['speedup']:.2f}"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
