"""``flexctrl modal-report MODEL --out DIR``: the modal analysis as figures and a summary."""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np

from flexctrl.commands.common import load_arm_from_args


def add_parser(subparsers) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "modal-report",
        help="mode shapes, boundary values and frequency maps as PNG files plus summary.json",
        description="Writes mode_shapes.png (Fig 2 of Subedi et al.), boundary_values.png (Fig 3), "
        "frequency_maps.png (Figs 6-7, exact and paper boundary inertia) and summary.json with "
        "timings "
        "and the lookup table's interpolation error.",
    )
    parser.add_argument("model", metavar="MODEL")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    parser.add_argument(
        "--payload", type=float, metavar="KG", help="payload for the maps (default: the file's)"
    )
    parser.add_argument(
        "--q",
        type=float,
        nargs="+",
        metavar="DEG",
        help="configuration for the mode shapes (degrees)",
    )
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument(
        "--step",
        type=float,
        default=15.0,
        metavar="DEG",
        help="grid step of the frequency maps (degrees)",
    )
    return parser


def run(args: argparse.Namespace) -> int:
    from flexctrl.modal.arm_modes import arm_modes
    from flexctrl.modal.lookup import interpolation_error_hz, modal_lookup
    from flexctrl.modal.mode_plots import (
        plot_boundary_values,
        plot_frequency_maps,
        plot_mode_shapes,
    )

    arm, q = load_arm_from_args(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    summary: dict = {"model": arm.name, "payload_kg": arm.payload.mass, "figures": []}

    timings = []
    for _ in range(20):
        start = time.perf_counter()
        arm_modes(arm, q)
        timings.append(time.perf_counter() - start)
    summary["all_modes_one_configuration_median_s"] = statistics.median(timings)

    summary["figures"].append(
        str(plot_mode_shapes(arm, (0.0, arm.payload.mass or 2.0), out / "mode_shapes.png"))
    )
    if arm.n_links == 3:
        summary["figures"].append(str(plot_boundary_values(arm, out / "boundary_values.png")))
        path, diff = plot_frequency_maps(arm, out / "frequency_maps.png", args.step)
        summary["figures"].append(str(path))
        summary["paper_vs_exact_inertia"] = diff

    lookups = []
    for link in range(arm.n_links):
        table = modal_lookup(arm, link, use_cache=False)
        lookups.append(
            {
                "link": link + 1,
                "scheduling_joints": [j + 1 for j in table.joints],
                "build_time_s": table.build_time_s,
                "grid_points": int(np.prod([table.grid_deg.size] * len(table.joints)))
                if table.joints
                else 1,
                "worst_interpolation_error_hz": interpolation_error_hz(arm, table, samples=100),
            }
        )
    summary["lookup_tables"] = lookups
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(json.dumps(summary, indent=2))
    return 0
