"""``flexctrl study STUDY``: run a batch study (grid of runs) into a result folder."""

from __future__ import annotations

import argparse
import sys


def add_parser(subparsers) -> argparse.ArgumentParser:
    from flexctrl.commands.common import add_backend_arguments

    parser = subparsers.add_parser(
        "study",
        help="run a study file's grid of runs (local process pool or Dask) and write its table "
        "and report",
        description="Validates the study file (every run's settings) before anything runs, then "
        "runs every run "
        "not yet recorded in the output folder, writing one record per run as it finishes, "
        "results.csv, "
        "study.json and report.md. A run that fails is recorded with its error and the study "
        "goes on. "
        "See docs/explanation/studies.md for the file format. Exit status: 0 when the study ran to "
        "its end "
        "(whatever the runs' status; --strict: 1 if a run failed), 2 for a broken study file, "
        "130 when interrupted.",
    )
    parser.add_argument("study", metavar="STUDY", help="study file, e.g. studies/quickstart.toml")
    parser.add_argument("--out", metavar="DIR", help="result folder (default: out/<study name>)")
    add_backend_arguments(parser)
    parser.add_argument(
        "--resume",
        action="store_true",
        help="continue an interrupted study in DIR: keep every recorded run, ok or failed "
        "(without it, runs recorded ok are kept and failed ones rerun)",
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a study-file key, e.g. seed=2 or grid.payload=[0,1] (repeatable)",
    )
    parser.add_argument(
        "--progress",
        choices=("auto", "bar", "lines", "none"),
        default="auto",
        help="progress on stderr (auto: a bar on a terminal, lines otherwise)",
    )
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress and no summary")
    parser.add_argument(
        "--blas-threads",
        default="auto",
        metavar="N",
        help="local pool only (not --workers 0 or --scheduler): BLAS threads per worker; auto "
        "(default): usable CPUs // workers, at least 1 (more threads than CPUs slow every run)",
    )
    parser.add_argument(
        "--no-report",
        action="store_true",
        help="skip report.md (draw it later with 'flexctrl report DIR')",
    )
    parser.add_argument(
        "--strict", action="store_true", help="exit with status 1 if any run failed"
    )
    return parser


def interrupt_hint(args: argparse.Namespace) -> str:
    """What to do after Ctrl-C outside the runs (the runner answers one inside them): the
    finished runs are saved, the report is written whole or not at all."""
    out = args.out or "out/<study name>"
    return (
        f"the finished runs are saved in {out}; 'flexctrl report {out}' draws the report, "
        f"'flexctrl study {args.study} --out {out} --resume' runs the rest"
    )


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from flexctrl.commands.common import stop_signals_interrupt
    from flexctrl.study.blas_threads import parse_blas_threads
    from flexctrl.study.runner import run_study
    from flexctrl.study.study_file import load_study

    blas_threads = parse_blas_threads(args.blas_threads)
    spec = load_study(args.study, overrides=args.set)
    if not args.quiet:
        for note in spec.unavailable_notes():
            print(f"{spec.name}: note: {note}", file=sys.stderr)
    out = Path(args.out) if args.out else Path("out") / spec.name
    with stop_signals_interrupt():
        result = run_study(
            spec,
            out,
            workers=args.workers,
            scheduler=args.scheduler,
            resume=args.resume,
            progress="none" if args.quiet else args.progress,
            report=not args.no_report,
            blas_threads=blas_threads,
        )
    c = result.counts
    if not args.quiet:
        print(
            f"{spec.name}: {c['ran']} run(s) this session ({c['skipped']} already recorded) on "
            f"{result.backend} "
            f"in {result.elapsed_s:.1f} s; grid: {c['ok']} ok, {c['failed']} failed, "
            f"{c['pending']} not run",
            file=sys.stderr,
        )
        for note in result.warnings:
            print(f"{spec.name}: note: {note}", file=sys.stderr)
        print(result.report or result.table_path)
    if result.interrupted:
        return 130
    return 1 if args.strict and c["failed"] else 0
