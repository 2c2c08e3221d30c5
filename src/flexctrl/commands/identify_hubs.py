"""``flexctrl identify-hubs MODEL``: fit the hub masses missing from Table 2 to Table 3."""

from __future__ import annotations

import argparse
import json


def add_parser(subparsers) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "identify-hubs",
        help="identify hub masses m_h2, m_h3 from Table 3 of Subedi et al. (2021)",
        description="Least-squares fit of the hub masses of joints 2 and 3 to the link-1 and "
        "link-2 "
        "frequencies of Table 3 (payload 0 and 2 kg, q2 = q3 = 0); prints the fit and the "
        "residuals "
        "of all twelve frequencies (the link-3 rows are an independent check).",
    )
    parser.add_argument(
        "model", metavar="MODEL", help="the three-link model file, e.g. models/subedi3link.toml"
    )
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="override a model-file key"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    return parser


def run(args: argparse.Namespace) -> int:
    from flexctrl.modal.identify import identify_hub_masses
    from flexctrl.spec.arm import load_arm

    fit = identify_hub_masses(load_arm(args.model, overrides=args.set))
    if args.json:
        print(
            json.dumps(
                {
                    "hub_masses_kg": {f"m_h{k}": v for k, v in fit.hub_masses.items()},
                    "rms_hz": fit.rms_hz,
                    "max_abs_hz": fit.max_abs_hz,
                    "residuals": [
                        dict(
                            zip(
                                (
                                    "payload_kg",
                                    "link",
                                    "mode",
                                    "table_hz",
                                    "model_hz",
                                    "residual_hz",
                                ),
                                r,
                            )
                        )
                        for r in fit.residuals_hz
                    ],
                },
                indent=2,
            )
        )
        return 0
    for joint, mass in fit.hub_masses.items():
        print(f"m_h{joint} = {mass:.4f} kg")
    print(f"fit over links 1-2: rms {fit.rms_hz:.4f} Hz, max |residual| {fit.max_abs_hz:.4f} Hz")
    print(
        f"{'payload kg':>10} {'link':>4} {'mode':>4} {'Table 3 Hz':>10} {'model Hz':>10} "
        f"{'residual Hz':>11}"
    )
    for payload, link, mode, ref, model, res in fit.residuals_hz:
        print(f"{payload:10.1f} {link:4d} {mode:4d} {ref:10.2f} {model:10.4f} {res:11.4f}")
    return 0
