"""``flexctrl report DIR``: redraw a study's report from its result folder alone."""

from __future__ import annotations

import argparse


def add_parser(subparsers) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "report",
        help="redraw report.md and figures of a study folder from results.csv, study.json and "
        "runs/",
        description="Draws the report of a study's result folder without running anything: maps "
        "of a metric "
        "over two grid columns, controller ranking per payload, worst cases with their "
        "trajectories, "
        "timing and failed runs. Options override the study's [report] table.",
    )
    parser.add_argument("dir", metavar="DIR", help="a folder written by 'flexctrl study'")
    parser.add_argument("--metric", metavar="NAME", help="the metric to map, rank and sort by")
    parser.add_argument(
        "--map-axes",
        nargs=2,
        metavar=("X", "Y"),
        help="the two grid columns of the maps, e.g. q2 q3",
    )
    parser.add_argument("--worst", type=int, metavar="N", help="how many worst runs to show")
    return parser


def interrupt_hint(args: argparse.Namespace) -> str:
    """What to do after Ctrl-C: the report is written whole or not at all."""
    return f"report.md is unchanged; 'flexctrl report {args.dir}' draws it again"


def run(args: argparse.Namespace) -> int:
    from flexctrl.study.report import write_report

    print(write_report(args.dir, metric=args.metric, map_axes=args.map_axes, worst=args.worst))
    return 0
