"""``flexctrl modes MODEL``: natural frequencies of every link (clamped-mass modes)."""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from flexctrl.commands.common import add_model_arguments, fidelity_from_args, load_arm_from_args
from flexctrl.errors import SpecError
from flexctrl.modal.boundary import boundary_values
from flexctrl.spec.arm import MAX_MODES


def add_parser(subparsers) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "modes",
        help="per-link natural frequencies (Hz) at a configuration and payload",
        description="Solves the clamped-mass eigenproblem of each link (Subedi et al. 2021, Eqs "
        "28-40) "
        "with boundary values from the outboard links, hubs and payload at the given configuration "
        "(Eqs 69-73). Angles in degrees, payload in kg, frequencies in Hz.",
    )
    add_model_arguments(parser)
    parser.add_argument(
        "--n-modes",
        type=int,
        metavar="N",
        help=f"modes per link, 0..{MAX_MODES} (default: the model file's, or N of --fidelity "
        "amm:N)",
    )
    parser.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object: {'links': [{'frequencies_hz': [...]}, ...]}",
    )
    return parser


def _n_modes(args: argparse.Namespace) -> int | None:
    fidelity = fidelity_from_args(args)
    if args.n_modes is not None:
        if not 0 <= args.n_modes <= MAX_MODES:
            raise SpecError(
                f"value {args.n_modes!r} is out of range; allowed: an integer from 0 to "
                f"{MAX_MODES}",
                key="--n-modes",
            )
        return args.n_modes
    if fidelity is None:
        return None
    return fidelity.modes_per_link if fidelity.kind in ("amm", "rigid") else None


def run(args: argparse.Namespace) -> int:
    arm, q = load_arm_from_args(args)
    fidelity = fidelity_from_args(args)
    n_modes = _n_modes(args)
    links = []
    if fidelity is not None and fidelity.kind == "fem":
        from flexctrl.modal.fem_modes import link_frequencies_fem

        elements = fidelity.count
        if elements is None:  # parse_fidelity gives every 'fem' fidelity its element count
            raise SpecError(f"fidelity {fidelity} has no element count; allowed: 'fem:N'")
        for i in range(arm.n_links):
            count = n_modes if n_modes is not None else arm.links[i].n_modes
            links.append(
                {
                    "link": i + 1,
                    "frequencies_hz": link_frequencies_fem(arm, q, i, count, elements).tolist(),
                }
            )
    else:
        from flexctrl.modal.arm_modes import link_modes

        for i in range(arm.n_links):
            modes = link_modes(arm, q, i, n_modes)
            links.append({"link": i + 1, "frequencies_hz": modes.frequency_hz.tolist()})
    for i, entry in enumerate(links):
        bv = boundary_values(arm, q, i)
        entry["boundary"] = {
            "m_D_kg": float(bv.m),
            "J_D_kg_m2": float(bv.J),
            "M_D_kg_m": float(bv.M),
        }
    result = {
        "model": arm.name,
        "payload_kg": arm.payload.mass,
        "q_deg": [math.degrees(a) for a in q],
        "boundary_inertia": arm.boundary_inertia,
        "fidelity": str(fidelity)
        if fidelity
        else "amm (modes per link: "
        + ", ".join(str(len(e["frequencies_hz"])) for e in links)
        + ")",
        "links": links,
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(
        f"{arm.name}: payload {arm.payload.mass:g} kg, q = "
        f"{np.round([math.degrees(a) for a in q], 3).tolist()} deg, "
        f"boundary_inertia = {arm.boundary_inertia}"
    )
    for entry in links:
        freqs = ", ".join(f"{f:.4f}" for f in entry["frequencies_hz"])
        b = entry["boundary"]
        print(
            f"link {entry['link']}: [{freqs}] Hz   (m_D {b['m_D_kg']:.4f} kg, J_D "
            f"{b['J_D_kg_m2']:.4f} kg m^2, M_D {b['M_D_kg_m']:.4f} kg m)"
        )
    return 0
