"""Studies side by side: each study's first pass and a repeated pass, alternated round by round.

``python benchmarks/studies_side_by_side.py --study A --study B [--repeats N] [--set K=V]``
(default: ``studies/quickstart_finest.toml`` then ``studies/quickstart_auto.toml``) runs, for every
round and every study in turn, a fresh Python process that runs the study twice into new folders:
the *first pass* (nothing in the process: models built, designs made, fidelity choices made; the
compiled-library cache on disk as it is) and a *repeated pass* in the same process (its worker cache
holds the models, designs and choices of the first).  Alternating the studies round by round lets
the machine's load move them together; the figures are each study's wall time per pass, the summed
per-run wall time (``results.csv``'s ``wall_time_s``), and the ratios of every study to the first
one (of the medians, and round by round for the first pass).  ``--set KEY=VALUE`` overrides apply to
every study.  Each pass's table is compared with the first pass's, every column but the timing and
memory ones (``tables_identical``).
"""

from __future__ import annotations

import csv
import json
import os
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from flexctrl.errors import FlexctrlError
from flexctrl.spec.shipped import data_root

REPO = data_root()
DEFAULT_STUDIES = (
    REPO / "studies" / "quickstart_finest.toml",
    REPO / "studies" / "quickstart_auto.toml",
)
#: Columns of results.csv that differ between any two passes (timings, memory, the worker's name).
VOLATILE = (
    "wall_time_s",
    "peak_memory_mb",
    "bytes_written",
    "worker",
    "choice_time_s",
    "controller_time_median",
    "controller_time_p95",
    "controller_time_max",
)

_PASSES = """
import json, sys, time
from flexctrl.study.runner import run_study
from flexctrl.study.study_file import load_study
study, overrides = sys.argv[1], json.loads(sys.argv[2])
outs, workers = sys.argv[3:-1], int(sys.argv[-1])
spec, walls = load_study(study, overrides=overrides), []
for out in outs:
    start = time.perf_counter()
    run_study(spec, out, workers=workers, progress="none", report=False)
    walls.append(time.perf_counter() - start)
print(json.dumps(walls))
"""


def read_table(path: Path) -> list[dict[str, str]]:
    """``results.csv`` rows, sorted by run id."""
    with open(path, newline="") as fh:
        return sorted(csv.DictReader(fh), key=lambda row: row["run_id"])


def stable_columns(rows: list[dict[str, str]]) -> list[tuple]:
    """The rows without :data:`VOLATILE` columns, for comparing two passes."""
    return [tuple((k, v) for k, v in row.items() if k not in VOLATILE) for row in rows]


def run_passes(
    study: Path, passes: int, workers: int, folder: Path, overrides: Sequence[str] = ()
) -> dict[str, Any]:
    """One fresh process running ``study`` (with ``overrides``, as ``flexctrl study --set``)
    ``passes`` times.

    Returns wall times, summed run times and status counts.
    """
    outs = [folder / f"pass{i + 1}" for i in range(passes)]
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            _PASSES,
            str(study),
            json.dumps(list(overrides)),
            *map(str, outs),
            str(workers),
        ],
        capture_output=True,
        text=True,
        check=False,
        env=os.environ.copy(),
    )
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no output"])[-1]
        raise FlexctrlError(
            f"the passes of study '{study}' failed (exit {done.returncode}): {last}"
        )
    walls = json.loads(done.stdout.strip().splitlines()[-1])
    tables = [read_table(out / "results.csv") for out in outs]
    return {
        "wall_s": walls,
        "summed_run_wall_s": [sum(float(r["wall_time_s"] or 0) for r in t) for t in tables],
        "ok": [sum(r["status"] == "ok" for r in t) for t in tables],
        "failed": [sum(r["status"] == "failed" for r in t) for t in tables],
        "tables_identical": all(stable_columns(t) == stable_columns(tables[0]) for t in tables[1:]),
        "peak_memory_mb": [
            max((float(r["peak_memory_mb"]) for r in t if r["peak_memory_mb"]), default=None)
            for t in tables
        ],
        "folders": [str(o) for o in outs],
    }


def bench_studies(
    studies: Sequence[str | Path] = DEFAULT_STUDIES,
    *,
    rounds: int = 1,
    passes: int = 2,
    workers: int = 0,
    keep: str | Path | None = None,
    overrides: Sequence[str] = (),
) -> dict[str, Any]:
    """Measure what the module docstring describes; a JSON-ready dict.

    ``overrides`` (``KEY=VALUE``, as ``flexctrl study --set``) apply to every study (``flexctrl
    bench studies`` loads each study with them before any pass; a pass whose study does not load
    raises :class:`~flexctrl.errors.FlexctrlError` with the pass's last error line).
    """
    folder = (
        Path(keep) if keep is not None else Path(tempfile.mkdtemp(prefix="flexctrl-bench-studies-"))
    )
    names = [Path(s).stem for s in studies]
    results: dict[str, list[dict[str, Any]]] = {name: [] for name in names}
    for r in range(rounds):
        for study, name in zip(studies, names):
            results[name].append(
                run_passes(Path(study), passes, workers, folder / f"round{r + 1}" / name, overrides)
            )
    per: dict[str, Any] = {}
    for name in names:
        rows = results[name]
        per[name] = {
            "first_pass_s": statistics.median(x["wall_s"][0] for x in rows),
            "repeated_pass_s": statistics.median(x["wall_s"][-1] for x in rows)
            if passes > 1
            else None,
            "first_pass_summed_run_wall_s": statistics.median(
                x["summed_run_wall_s"][0] for x in rows
            ),
            "tables_identical": all(x["tables_identical"] for x in rows),
            "rounds": rows,
        }
    base = per[names[0]]
    ratios = {
        name: {
            "first_pass": per[name]["first_pass_s"] / base["first_pass_s"],
            "repeated_pass": (
                per[name]["repeated_pass_s"] / base["repeated_pass_s"] if passes > 1 else None
            ),
            "first_pass_rounds": [
                x["wall_s"][0] / b["wall_s"][0] for x, b in zip(results[name], results[names[0]])
            ],
        }
        for name in names[1:]
    }
    return {
        "studies": [str(s) for s in studies],
        "overrides": list(overrides),
        "rounds": rounds,
        "passes": passes,
        "workers": workers,
        "results": per,
        "ratio_to_first_study": ratios,
        "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "folder": str(folder),
    }


def format_studies(result: dict[str, Any]) -> str:
    """Human-readable lines of :func:`bench_studies`."""
    lines = [
        f"studies_side_by_side: {result['rounds']} round(s), {result['passes']} passes per "
        "process, "
        f"workers {result['workers']} (load average {result['load_average_1min']})"
        + (
            f"; every study with --set {' --set '.join(result['overrides'])}"
            if result.get("overrides")
            else ""
        )
    ]
    for name, r in result["results"].items():
        rep = (
            "" if r["repeated_pass_s"] is None else f", repeated pass {r['repeated_pass_s']:.1f} s"
        )
        lines.append(
            f"  {name:28s} first pass {r['first_pass_s']:.1f} s (runs summed "
            f"{r['first_pass_summed_run_wall_s']:.1f} s){rep}; tables identical across passes: "
            f"{r['tables_identical']}"
        )
    first = next(iter(result["results"]))
    for name, q in result["ratio_to_first_study"].items():
        rep = "" if q["repeated_pass"] is None else f", repeated pass {q['repeated_pass']:.2f}"
        each = ", ".join(f"{x:.2f}" for x in q["first_pass_rounds"])
        lines.append(f"  {name} / {first}: first pass {q['first_pass']:.2f} (rounds: {each}){rep}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """The command line (see the module docstring); exit status 2 on bad arguments."""
    import argparse

    from flexctrl.errors import SpecError
    from flexctrl.study.study_file import load_study

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--study", action="append", default=None, help="a study file (repeat)")
    parser.add_argument("--repeats", type=int, default=3, help="rounds (default 3)")
    parser.add_argument("--workers", type=int, default=0, help="study workers (0: in process)")
    parser.add_argument(
        "--keep", default=None, metavar="DIR", help="write the passes' folders here"
    )
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if args.repeats < 1 or args.workers < 0:
        parser.error("allowed: --repeats >= 1 and --workers >= 0")
    studies = args.study or DEFAULT_STUDIES
    try:
        for study in studies:  # a bad study or override is refused before any pass runs
            load_study(study, overrides=args.set)
    except SpecError as exc:
        parser.error(str(exc))
    result = bench_studies(
        studies, rounds=args.repeats, workers=args.workers, keep=args.keep, overrides=args.set
    )
    print(json.dumps(result, indent=2) if args.json else format_studies(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
