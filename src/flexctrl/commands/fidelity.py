"""``flexctrl fidelity SCENE --tol METRES``: the cheapest model that keeps a scene's tip within a
tolerance.

Runs :func:`flexctrl.scenes.auto.choose_fidelity` on a ``kind = "arm"``
scene, or :func:`~flexctrl.scenes.auto_closed_loop.choose_closed_loop_fidelity` on a
``kind = "closed_loop"`` scene (the plant's fidelity is chosen, the controller
designed once on ``controller_fidelity``, else on the scene's own plant fidelity,
``amm:2`` when that is ``auto``; ``--controller``
overrides the scene's controller file), the scene's own ``fidelity`` ignored, and
prints the choice with its evidence:
the modal-bandwidth rule, every rung simulated (step, wall time, distance to the
next rung, error estimate, error against the reference) and the reference with
its convergence checks.  ``--json`` prints one JSON object whose first keys are
``choice`` (a ``--fidelity`` spelling), ``estimated_error`` (m),
``reference_error`` (m) and ``cost_ratio`` (the choice's integration wall time
over the reference's).

Exit status: 0 with a choice; 2 for bad input (a :class:`~flexctrl.errors.SpecError`
naming the key); 3 when no rung meets the tolerance (the message names the best
achievable estimate; with ``--json`` the evidence is still printed to stdout).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math


def add_parser(subparsers) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "fidelity",
        help="choose the cheapest model (rigid, amm:N) that keeps a scene's tip within a tolerance",
        description="Simulates an arm scene (or a closed loop with the plant) on the ladder "
        "rigid, amm:1, ..., amm:TOP, estimates each rung's tip error "
        "by its distance to the next rung (times a safety factor), starts the walk where the "
        "torque's bandwidth "
        "says, and checks the choice against a converged reference (amm:TOP+1 at a small RK4 "
        "step). Units: m, s.",
    )
    parser.add_argument(
        "scene",
        metavar="SCENE",
        help="arm or closed-loop scene file, e.g. studies/scenes/bangbang.toml",
    )
    parser.add_argument(
        "--controller",
        metavar="FILE",
        help="controller file for a closed-loop scene (default: the scene's 'controller')",
    )
    parser.add_argument(
        "--tol",
        type=float,
        metavar="METRES",
        help="tolerance on the largest tip-position error (m); default: the scene's 'tolerance'",
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override any scene key, e.g. duration=0.5 or payload=4.0 (repeatable)",
    )
    parser.add_argument(
        "--top", type=int, default=4, metavar="N", help="highest candidate amm:N (1..5, default 4)"
    )
    parser.add_argument(
        "--reference", metavar="F", help="reference model amm:R, TOP < R <= 6 (default amm:TOP+1)"
    )
    parser.add_argument(
        "--safety",
        type=float,
        default=2.0,
        metavar="S",
        help="factor on the distance to the next rung that makes the error estimate (default 2)",
    )
    parser.add_argument(
        "--json", action="store_true", help="print one JSON object instead of a table"
    )
    return parser


def _checked(args: argparse.Namespace, scene) -> float:
    """The tolerance (m), after the scene kind and the options are checked."""
    from flexctrl.errors import SpecError
    from flexctrl.fidelity.ladder import check_tolerance

    if scene.kind not in ("arm", "closed_loop"):
        raise SpecError(
            f"scene kind '{scene.kind}' is not supported; allowed: 'arm', 'closed_loop'",
            source=args.scene,
            key="kind",
        )
    if args.controller is not None and scene.kind != "closed_loop":
        raise SpecError(
            f"value '{args.controller}' is not allowed for a kind = \"{scene.kind}\" scene; "
            "allowed: --controller with a closed-loop scene only",
            source=args.scene,
            key="--controller",
        )
    tolerance = scene.tolerance if scene.kind == "arm" else scene.plant.tolerance
    if args.tol is not None:
        return check_tolerance(args.tol, source=args.scene, key="--tol")
    if tolerance is None:
        raise SpecError(
            "is missing and the scene sets no 'tolerance'; allowed: a number > 0 (m)",
            source=args.scene,
            key="--tol",
        )
    return tolerance


def _choose_closed(args: argparse.Namespace, scene, tol: float):
    """The plant's fidelity of a closed-loop scene, its controller designed on the scene's model."""
    from flexctrl.scenes.auto_closed_loop import choose_closed_loop_fidelity
    from flexctrl.scenes.loop_setup import pin_design
    from flexctrl.scenes.run_closed_loop_scene import check_auto
    from flexctrl.spec.fidelity import parse_fidelity

    design = scene.controller_fidelity
    if design is None and scene.plant.fidelity.kind != "auto":
        design = scene.plant.fidelity  # the model the scene's controller is designed on
    auto = dataclasses.replace(
        scene,
        controller_fidelity=design,
        plant=dataclasses.replace(scene.plant, fidelity=parse_fidelity("auto"), tolerance=tol),
    )
    check_auto(auto, args.controller)
    return choose_closed_loop_fidelity(
        pin_design(auto),
        tol,
        controller=args.controller,
        top=args.top,
        reference=args.reference,
        safety=args.safety,
        walk=auto.plant.fidelity_walk,
        checks=auto.plant.fidelity_checks,
    )


def run(args: argparse.Namespace) -> int:
    """Choose, and print the choice and its evidence (a table, or JSON)."""
    from flexctrl.fidelity.ladder import ToleranceUnreachable
    from flexctrl.spec.scene import load_scene

    scene = load_scene(args.scene, args.set)
    tol = _checked(args, scene)
    try:
        choice = _choose_closed(args, scene, tol) if scene.kind == "closed_loop" else None
        if choice is None:
            from flexctrl.scenes.auto import choose_fidelity

            choice = choose_fidelity(
                scene,
                tol,
                top=args.top,
                reference=args.reference,
                safety=args.safety,
                checks=scene.fidelity_checks,
            )
    except ToleranceUnreachable as exc:
        if args.json:
            print(
                json.dumps(
                    {"choice": None, "error": str(exc), **exc.evidence},
                    indent=2,
                    default=_json_default,
                )
            )
        raise
    data = choice.to_dict()
    if args.json:
        print(json.dumps(data, indent=2, default=_json_default))
        return 0
    print(format_table(data))
    return 0


def _step_check(conv: dict) -> str:
    """The reference's step check, as made (or "not made", with ``fidelity_checks =
    "tolerance"``)."""
    if "step_halving_m" in conv:
        return f"halving its step moves the tip {conv['step_halving_m']:.2e} m; "
    if "step_error_linear_m" in conv:
        return f"its step error (linear estimate) {conv['step_error_linear_m']:.2e} m; "
    return f"step check {conv['step_check']}; "


def _rung_below(conv: dict) -> str:
    """The reference's distance from the rung below it (not run with ``fidelity_checks =
    "tolerance"``)."""
    if conv["rung_below_m"] is None:
        return f"{conv['rung_below']} not run; "
    return f"{conv['rung_below']} differs by {conv['rung_below_m']:.2e} m; "


def format_table(data: dict) -> str:
    """A readable report of :meth:`FidelityChoice.to_dict` output."""
    rule = data["bandwidth_rule"]
    ref = data["reference"]
    conv = ref["convergence"]
    bw = rule["excitation_bandwidth_hz"]
    lines = [
        f"scene {data['scene']}: tolerance {data['tolerance_m']:.3g} m on the tip position",
        (
            f"bandwidth rule: {rule['energy_fraction']:.3g} of the torque energy below {bw:.3g} "
            "Hz; modes below "
            f"{rule['cutoff_hz']:.3g} Hz kept per link {rule['modes_kept_per_link']} -> start at "
            f"{rule['start']}"
        )
        if bw is not None
        else f"bandwidth rule: no torque; start at {rule['start']} (the initial state's lowest "
        "rung)",
        (
            f"reference {ref['fidelity']} ({ref['integrator']}, dt {ref['dt_s']:.3g} s, "
            f"omega_max*dt {ref['omega_max_dt']:.2f}): "
            + _step_check(conv)
            + _rung_below(conv)
            + f"integration {ref['wall_time_s']:.3g} s"
        ),
        "",
        f"{'rung':>7} {'dt (s)':>9} {'wall (s)':>9} {'to next (m)':>12} {'estimate (m)':>12} "
        f"{'vs ref (m)':>11} {'cost':>8}",
    ]
    for c in data["candidates"]:
        mark = "  <- choice" if c["fidelity"] == data["choice"] else ""
        lines.append(
            f"{c['fidelity']:>7} {c['dt_s']:9.3g} {c['wall_time_s']:9.3g} "
            f"{_f(c.get('distance_to_next_m'))} "
            f"{_f(c.get('estimated_error_m'))} {c['reference_error_max_m']:11.2e} "
            f"{c['cost_ratio']:8.3g}{mark}"
        )
    lines += [
        "",
        f"choice {data['choice']} ({data['integrator']}, dt {data['dt_s']:.3g} s): estimated error "
        f"{data['estimated_error']:.2e} m, error against the reference "
        f"{data['reference_error']:.2e} m, "
        f"cost {data['cost_ratio']:.3g} x the reference's integration time",
    ]
    return "\n".join(lines)


def _f(value) -> str:
    return f"{'-':>12}" if value is None else f"{value:12.2e}"


def _json_default(value):
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return str(value)
