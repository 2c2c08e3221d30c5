"""``flexctrl tune TUNING --out DIR``: tune a controller file over closed-loop scenarios."""

from __future__ import annotations

import argparse
import sys


def add_parser(subparsers) -> argparse.ArgumentParser:
    from flexctrl.commands.common import add_backend_arguments

    parser = subparsers.add_parser(
        "tune",
        help="tune a controller file's keys over closed-loop scenarios and write the tuned file "
        "and a report",
        description="Validates the tuning file (parameter keys against the controller file, "
        "bounds, the scenario "
        "study, the objective metric) before anything runs; then evaluates candidates as "
        "nonlinear closed-loop runs "
        "on every scenario (local process pool or Dask), keeping every run in DIR/runs so a "
        "killed tuning resumes "
        "with the same command. Writes DIR/controller.toml, DIR/tuning.json, "
        "DIR/evaluations.jsonl and "
        "DIR/report.md. See docs/guide/tune-a-controller.md. Exit status: 0 tuned, 2 a broken "
        "tuning file, 3 no "
        "feasible candidate, "
        "130 interrupted (finished runs are kept).",
    )
    parser.add_argument("tuning", metavar="TUNING", help="tuning file, e.g. studies/tune_lqr.toml")
    parser.add_argument("--out", metavar="DIR", help="output folder (default: out/<tuning name>)")
    add_backend_arguments(parser)
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a tuning-file key, e.g. optimizer.evaluations=10 (repeatable)",
    )
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress lines")
    return parser


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from flexctrl.commands.common import stop_signals_interrupt
    from flexctrl.spec.tuning import load_tuning
    from flexctrl.tuning.tuner import tune

    spec = load_tuning(args.tuning, args.set)
    out = Path(args.out) if args.out else Path("out") / spec.name
    try:
        with stop_signals_interrupt():
            result = tune(
                spec, out, workers=args.workers, scheduler=args.scheduler, progress=not args.quiet
            )
    except KeyboardInterrupt:
        print(
            f"flexctrl tune: interrupted; the finished runs are kept in {out / 'runs'}: run the "
            "same command to "
            "resume",
            file=sys.stderr,
        )
        return 130
    s = result.summary
    print(
        f"{spec.name}: {spec.objective.statistic} {spec.objective.metric} "
        f"{s['initial_objective']:.6g} as shipped -> "
        f"{s['best_objective']:.6g} tuned ({s['evaluations']} candidates, "
        f"{s['feasible_evaluations']} feasible, "
        f"{result.wall_time_s:.0f} s)",
        file=sys.stderr,
    )
    print(out / "report.md")
    return 0
