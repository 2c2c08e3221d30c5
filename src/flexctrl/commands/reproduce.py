"""``flexctrl reproduce {subedi,pan} --out DIR [--reduced]``: a seed paper's tables and figures
beside flexctrl's."""

from __future__ import annotations

import argparse

from flexctrl.reproduce.reproduction import PAPERS


def add_parser(subparsers) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "reproduce",
        help="every table and figure of a seed paper beside flexctrl's, with verdicts "
        "(report.md, reproduction.json)",
        description="Runs what the paper reports and writes DIR/report.md (each table and figure "
        "in the paper's "
        "order, beside its printed numbers or described behaviour, with a verdict), "
        "DIR/reproduction.json (the "
        "items: item, paper, flexctrl, agrees, note) and DIR/figures/*.png. subedi: Subedi, "
        "Tyapin, Hovland "
        "(2021); pan: Pan, Scott, Ulsoy (1990).",
    )
    parser.add_argument("paper", choices=PAPERS, metavar="{" + ",".join(PAPERS) + "}")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    parser.add_argument(
        "--reduced",
        action="store_true",
        help="coarser grids and shorter runs, same code paths (CI)",
    )
    return parser


def run(args: argparse.Namespace) -> int:
    from flexctrl.reproduce.reproduction import reproduce_paper

    document = reproduce_paper(args.paper, args.out, args.reduced)
    items = document["items"]
    agree = sum(item["agrees"] for item in items)
    print(
        f"{args.out}/report.md: {agree} of {len(items)} items agree ({document['seconds']:.0f} s)"
    )
    for item in items:
        if not item["agrees"]:
            print(f"  differs: {item['item']}: paper {item['paper']}; flexctrl {item['flexctrl']}")
    return 0
