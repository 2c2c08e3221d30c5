"""``flexctrl linearize MODEL``: the linearisation at a static equilibrium, its modes and locked
frequencies."""

from __future__ import annotations

import argparse
import json
import math

from flexctrl.commands.common import add_model_arguments

# : A pole with Re s above this fraction of max(1, |s|) (1/s) is marked unstable (the rest is
# rounding).
UNSTABLE_TOL = 1e-9


def add_parser(subparsers) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "linearize",
        help="linearise at the static equilibrium of a configuration: modal frequencies and "
        "damping",
        description="Builds the model (default amm:2), solves the static equilibrium with the "
        "joints held at "
        "--q (degrees) against gravity, linearises it (python-control StateSpace, states q then "
        "qd) and prints "
        "one line per pole: frequency (Hz), damping ratio, real part and kind, unstable poles "
        "marked. With --locked, frequencies_hz lists the undamped natural "
        "frequencies of the flexible structure with the joints clamped, ascending.",
    )
    add_model_arguments(parser, fidelity_default="amm:2")
    parser.add_argument(
        "--locked",
        action="store_true",
        help="joints clamped: undamped frequencies of the flexible structure",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    return parser


def run(args: argparse.Namespace) -> int:
    from flexctrl.commands.common import fidelity_from_args, load_arm_from_args
    from flexctrl.dynamics.build import build_model
    from flexctrl.errors import warn_spec
    from flexctrl.linear import (
        equilibrium,
        holding_torque_excess,
        linearize,
        locked_frequencies,
        modal_summary,
    )

    arm, q = load_arm_from_args(args)
    fidelity = fidelity_from_args(args)
    model = build_model(arm, str(fidelity), reference_q=q)
    op = equilibrium(model, q)
    excess = holding_torque_excess(model, op)
    if excess:
        warn_spec(
            f"{excess} (the linearisation below is of an equilibrium the actuators cannot hold)",
            source=args.model,
            key="--q",
            stacklevel=2,
        )
    result = {
        "model": arm.name,
        "fidelity": str(model.fidelity),
        "payload_kg": arm.payload.mass,
        "q_deg": [math.degrees(a) for a in q],
        "n_states": model.n_x,
        "equilibrium_torque_Nm": op.u.tolist(),
        "static_tip_deflections_m": [
            float(v) for v in model.functions["deflection"](op.q)[0].full().ravel()
        ],
    }
    if args.locked:
        result["locked"] = True
        result["frequencies_hz"] = locked_frequencies(model, op).tolist()
    else:
        summary = modal_summary(linearize(model, op))
        result["locked"] = False
        result["frequencies_hz"] = summary.frequency_hz.tolist()
        result["damping_ratios"] = [None if math.isnan(z) else float(z) for z in summary.damping]
        result["eigenvalues_real_1_s"] = [float(s.real) for s in summary.eigenvalues]
        result["unstable"] = [
            bool(s.real > UNSTABLE_TOL * max(1.0, abs(s))) for s in summary.eigenvalues
        ]
        result["damping"] = arm.damping_summary(model.info.get("damping"))
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(
        f"{arm.name} ({result['fidelity']}), payload {arm.payload.mass:g} kg, q = "
        f"{[round(a, 3) for a in result['q_deg']]} deg"
    )
    print(
        f"  equilibrium torques {[round(v, 3) for v in result['equilibrium_torque_Nm']]} N m, "
        f"static link-tip deflections {[f'{v:.3e}' for v in result['static_tip_deflections_m']]} m"
    )
    if args.locked:
        print(
            "  locked-joint natural frequencies (Hz): "
            + ", ".join(f"{f:.4g}" for f in result["frequencies_hz"])
        )
        return 0
    print(_pole_table(summary.eigenvalues))
    print(_damping_note(result["damping"], result["q_deg"]))
    return 0


def _damping_note(damping: dict, q_deg: list[float]) -> str:
    """What the model's damping is, beside the poles' zeta it gives."""
    if damping["form"] == "modal":
        return (
            f"  damping: damping_form = 'modal', damping_zeta = {damping['zeta_coupled_modes']:g} "
            "on every coupled elastic mode at the model's configuration (joints free, no "
            "gravity); at other poses, with gravity or joint friction the poles' zeta moves "
            "from it"
        )
    ratios = damping["damping_ratio_per_clamped_mass_mode"]
    return (
        f"  damping: damping_form = '{damping['form']}', each link's damping_ratio {ratios} "
        "acts per clamped-mass mode of that link (Eq 68's form), not on the arm's coupled "
        "modes: the zeta column above is what it gives them. For a damping ratio on the "
        "coupled modes set damping_form = 'modal' and damping_zeta (e.g. --set "
        "damping_form=modal --set damping_zeta=0.01)"
    )


def _pole_table(eigenvalues) -> str:
    """One line per pole of the linearisation (of each complex pair the one with Im s > 0), UNSTABLE
    marked."""
    lines = [
        "  poles of the linearisation (torques held at the equilibrium's; f = |s| / 2 pi, "
        "zeta = -Re s / |s|; Re s > 0 grows):",
        f"    {'f (Hz)':>10}  {'zeta':>8}  {'Re s (1/s)':>11}  kind",
    ]
    unstable = 0
    largest = max((abs(s) for s in eigenvalues), default=0.0)
    for s in eigenvalues:
        magnitude = abs(s)
        rigid = magnitude <= UNSTABLE_TOL * largest  # zero to round-off
        kind = "oscillatory pair" if s.imag > 0 else ("rigid (s = 0)" if rigid else "real")
        zeta = f"{-s.real / magnitude + 0.0:8.4f}" if not rigid else f"{'-':>8}"
        zeta = zeta.replace("-0.0000", " 0.0000")
        mark = ""
        if s.real > UNSTABLE_TOL * max(1.0, magnitude) and not rigid:
            unstable += 1
            mark = (
                f"  UNSTABLE (grows as exp({s.real:.4g} t), doubling in "
                f"{math.log(2) / s.real:.3g} s)"
            )
        lines.append(f"    {magnitude / (2 * math.pi):10.4f}  {zeta}  {s.real:11.4g}  {kind}{mark}")
    lines.append(f"  {unstable} unstable pole(s)" if unstable else "  no unstable pole")
    return "\n".join(lines)
