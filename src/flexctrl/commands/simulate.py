"""``flexctrl simulate SCENE --out DIR``: run a scene file and write its results.

Writes ``trajectory.csv`` (see :mod:`flexctrl.sim.trajectory` for the columns),
``summary.json`` (scene settings, wall time, real-time factor, energy drift,
dominant FFT frequencies of every link's tip deflection) and PNG plots to DIR.
``--set KEY=VALUE`` overrides a scene key; ``--set controller.KEY=VALUE`` a key of the
closed-loop scene's controller file (validated like the file, before anything is built).
"""

from __future__ import annotations

import argparse
import json

from flexctrl.spec.fidelity import SPELLINGS

# : ``--set controller.KEY=VALUE`` overrides the controller file (of the scene or --controller), not
# the scene.
CONTROLLER_PREFIX = "controller."


def add_parser(subparsers) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "simulate",
        help="simulate a scene file (studies/scenes/*.toml) and write trajectory, summary and "
        "plots",
        description="Loads a scene (model, payload, fidelity, initial state, damping, input, "
        "integrator, "
        "step and duration), simulates it and writes trajectory.csv, summary.json and PNG plots "
        "to --out. "
        "Units are SI; angles in scene files are in degrees.",
    )
    parser.add_argument(
        "scene", metavar="SCENE", help="scene file, e.g. studies/scenes/free_vibration.toml"
    )
    parser.add_argument(
        "--out", required=True, metavar="DIR", help="output folder (created if missing)"
    )
    parser.add_argument(
        "--fidelity", metavar="F", help=f"override the scene's fidelity: {SPELLINGS}"
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override any scene key, e.g. duration=0.5 or initial.qf.qf31=0.05, or with "
        "controller.KEY a key of the controller file, e.g. controller.sample_time=0.005 "
        "(repeatable)",
    )
    parser.add_argument(
        "--controller",
        metavar="FILE",
        help="controller settings (controllers/*.toml) for a closed-loop scene (kind = "
        '"closed_loop")',
    )
    parser.add_argument("--no-plots", action="store_true", help="write no PNG files")
    parser.add_argument(
        "--json", action="store_true", help="print summary.json to stdout instead of a short report"
    )
    return parser


def run(args: argparse.Namespace) -> int:
    """Run the scene, write its files and print a short report (or ``summary.json``)."""
    from flexctrl.scenes import run_scene
    from flexctrl.spec.scene import load_scene

    overrides = [o for o in args.set if not o.strip().startswith(CONTROLLER_PREFIX)]
    controller_overrides = [
        o.strip()[len(CONTROLLER_PREFIX) :]
        for o in args.set
        if o.strip().startswith(CONTROLLER_PREFIX)
    ]
    if args.fidelity is not None:
        overrides.append(f"fidelity={json.dumps(args.fidelity)}")
    scene = load_scene(args.scene, overrides)
    options = _run_options(args, scene, controller_overrides)
    result = run_scene(scene, args.out, **options)
    s = result.summary
    if args.json or (scene.kind != "closed_loop" and "energy" not in s):
        print(json.dumps(s, indent=2, default=str))
        return 0
    lines = _closed_loop_report(scene, s) if scene.kind == "closed_loop" else _arm_report(scene, s)
    print("\n".join([*lines, f"  wrote {len(result.files)} files to {args.out}"]))
    return 0


def _run_options(args: argparse.Namespace, scene, controller_overrides: list[str]) -> dict:
    """The runner's options: plots, the controller file and its overrides (checked here)."""
    from flexctrl.errors import SpecError

    options: dict = {"plots": False if args.no_plots else None}
    if scene.kind != "closed_loop" and (args.controller is not None or controller_overrides):
        key = (
            "--controller"
            if args.controller is not None
            else f"--set {CONTROLLER_PREFIX}{controller_overrides[0]}"
        )
        raise SpecError(
            f"scene kind '{scene.kind}' runs no controller; allowed: a kind = \"closed_loop\" "
            "scene",
            source=args.scene,
            key=key,
        )
    if args.controller is not None:
        options["controller"] = args.controller
    if controller_overrides:
        from flexctrl.spec.controller_reader import load_controller

        file = args.controller or scene.controller
        if file is None:
            raise SpecError(
                "the scene names no controller file to override; allowed: a scene 'controller' "
                "key or --controller FILE",
                source=args.scene,
                key="--set controller.KEY",
            )
        load_controller(file, controller_overrides)  # refused here, before the model is built
        options["overrides"] = controller_overrides
    return options


def _closed_loop_report(scene, s: dict) -> list[str]:
    m = s["metrics"]
    return [
        f"{scene.name} with {s['controller']['kind']} ({s['controller']['file']}): tip "
        f"residual rms {m['tip_residual_rms']:.3e} m, "
        f"peak {m['tip_residual_peak']:.3e} m, settling {m['settling_time']:.3g} s, peak "
        f"deflection {m['peak_deflection']:.3e} m, "
        f"peak torque {', '.join(f'{v:.3g}' for v in m['peak_torque'])} N m, controller "
        f"median {m['controller_time_median'] * 1e3:.3g} ms, "
        f"fallbacks {m['fallbacks']}"
    ]


def _arm_report(scene, s: dict) -> list[str]:
    energy = s["energy"]
    freqs = "; ".join(
        f"{k}: {', '.join(f'{f:.4g}' for f in v) or '-'} Hz"
        for k, v in s["dominant_frequencies_hz"].items()
    )
    return [
        f"{scene.name}: {s['n_steps']} {s['integrator']} steps of {s['dt']:g} s in "
        f"{s['wall_time_s']:.3g} s "
        f"({s['realtime_factor']:.1f}x real time{', compiled' if s.get('compiled') else ''})",
        f"  energy: E_total(end) - E_total(0) = {energy['drift_rel']:+.3e}, max |E_total - "
        "E_total(0) - torque work| = "
        f"{energy['balance_error_max_rel']:.3e} (damping included), relative to "
        f"{energy['scale_J']:.4g} J exchanged",
        f"  dominant frequencies of the link-tip deflections: {freqs}",
    ]
