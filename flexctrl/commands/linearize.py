"""``flexctrl linearize MODEL``: the linearisation at a static equilibrium, its modes and locked frequencies."""

from __future__ import annotations

import argparse
import json
import math

from flexctrl.commands.common import add_model_arguments


def add_parser(subparsers) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "linearize",
        help="linearise at the static equilibrium of a configuration: modal frequencies and damping",
        description="Builds the model (default amm:2), solves the static equilibrium with the joints held at "
        "--q (degrees) against gravity, linearises it (python-control StateSpace, states q then qd) and prints "
        "its modal frequencies (Hz) and damping ratios. With --locked, frequencies_hz lists the undamped natural "
        "frequencies of the flexible structure with the joints clamped, ascending.",
    )
    add_model_arguments(parser, fidelity_default="amm:2")
    parser.add_argument("--locked", action="store_true", help="joints clamped: undamped frequencies of the flexible structure")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    return parser


def run(args: argparse.Namespace) -> int:
    from flexctrl.commands.common import fidelity_from_args, load_arm_from_args
    from flexctrl.dynamics.build import build_model
    from flexctrl.linear import equilibrium, linearize, locked_frequencies, modal_summary

    arm, q = load_arm_from_args(args)
    fidelity = fidelity_from_args(args)
    model = build_model(arm, str(fidelity), reference_q=q)
    op = equilibrium(model, q)
    result = {
        "model": arm.name,
        "fidelity": str(model.fidelity),
        "payload_kg": arm.payload.mass,
        "q_deg": [math.degrees(a) for a in q],
        "n_states": model.n_x,
        "equilibrium_torque_Nm": op.u.tolist(),
        "static_tip_deflections_m": [float(v) for v in model.functions["deflection"](op.q)[0].full().ravel()],
    }
    if args.locked:
        result["locked"] = True
        result["frequencies_hz"] = locked_frequencies(model, op).tolist()
    else:
        summary = modal_summary(linearize(model, op))
        result["locked"] = False
        result["frequencies_hz"] = summary.frequency_hz.tolist()
        result["damping_ratios"] = [None if math.isnan(z) else float(z) for z in summary.damping]
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"{arm.name} ({result['fidelity']}), payload {arm.payload.mass:g} kg, q = {[round(a, 3) for a in result['q_deg']]} deg")
    print(f"  equilibrium torques {[round(v, 3) for v in result['equilibrium_torque_Nm']]} N m, "
          f"static link-tip deflections {[f'{v:.3e}' for v in result['static_tip_deflections_m']]} m")
    label = "locked-joint natural frequencies" if args.locked else "modal frequencies of the linearisation"
    print(f"  {label} (Hz): " + ", ".join(f"{f:.4g}" for f in result["frequencies_hz"]))
    return 0
