"""``flexctrl export CONTROLLER --scene SCENE --out DIR``: a designed controller as C code.

The scene gives what a controller file alone does not: the design model (arm, payload,
fidelity, gravity, damping), the design configuration, the move whose reference table the
library carries, and the closed loop recorded for ``make -C DIR check`` (plant, plant
step, duration, initial state, noise).  The controller is stepped in Python through that
loop (:class:`~flexctrl.control.cexport.StepRecorder`); the library is written with the
recording (:func:`~flexctrl.control.cexport.export_c`).  ``--check`` then builds it, runs
the harness and prints the C step time beside Python's.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import time
from pathlib import Path

import numpy as np

#: ``--set controller.KEY=VALUE`` overrides the controller file, not the scene.
CONTROLLER_PREFIX = "controller."


def add_parser(subparsers) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "export",
        help="write a designed controller as a C library with a replay harness",
        description="Designs CONTROLLER on SCENE's design model, runs the scene's closed loop "
        "with it in Python (recorded), and writes a self-contained C library to --out: "
        "flexctrl_controller.h (measurement and torque order, units), the law, the reference "
        "table, a Makefile and a harness; `make -C DIR check` replays the loop in C and "
        "compares the torques. Exports LQR/LQG and the linear MPC.",
    )
    parser.add_argument(
        "controller", metavar="CONTROLLER", help="controller file, e.g. controllers/lqr.toml"
    )
    parser.add_argument(
        "--scene",
        required=True,
        metavar="SCENE",
        help='closed-loop scene (kind = "closed_loop"), e.g. studies/scenes/move_joint1_30deg.toml',
    )
    parser.add_argument(
        "--out", required=True, metavar="DIR", help="output folder (created if missing)"
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scene key (duration=4), or with controller.KEY a key of the controller "
        "file (controller.osqp.max_iter=30); repeatable",
    )
    parser.add_argument(
        "--qp-eps",
        type=float,
        metavar="EPS",
        help="linear MPC: the QP tolerance in C (default 1/100 of the controller's eps_abs)",
    )
    parser.add_argument(
        "--no-record", action="store_true", help="write no replay (nothing to check)"
    )
    parser.add_argument(
        "--check",
        action="store_true",
        help="then build and run `make -C DIR check`, and print the C step time beside Python's",
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=3,
        metavar="N",
        help="timing passes of Python's step over the recording (default 3)",
    )
    return parser


def run(args: argparse.Namespace) -> int:
    """Design, record, export; print what was written (and the check with --check)."""
    from flexctrl.control.cexport import StepRecorder
    from flexctrl.control.controller import Controller
    from flexctrl.errors import SpecError

    setup = _setup(args)
    ctrl = setup.controller
    replay, python = None, {}
    try:
        if type(ctrl).export_c is Controller.export_c:  # refused before a run is recorded
            ctrl.export_c(args.out)
        if not args.no_record:
            recorder = StepRecorder(ctrl, _source(setup, args))
            _record(setup, recorder)
            replay = recorder.replay()
            python = _python_step_times(ctrl, replay, args.repeats)
        export = ctrl.export_c(args.out, replay=replay, qp_eps=args.qp_eps)
    except SpecError as exc:
        if exc.source is not None:
            raise
        raise SpecError(exc.message, source=args.controller, key=exc.key) from None
    (Path(args.out) / "python_side.json").write_text(json.dumps(python, indent=2) + "\n")
    print(
        f"wrote {len(export.files)} files to {args.out} (route {export.route}, "
        f"{export.samples} recorded samples); check: make -C {args.out} check"
    )
    if python:
        print(_times_line("Python ctrl.step", python))
    if args.check:
        return _check(Path(args.out), python)
    return 0


def _setup(args: argparse.Namespace):
    """The scene's loop with the controller designed from the file (and the overrides)."""
    from flexctrl.errors import SpecError
    from flexctrl.scenes.loop_setup import build_loop, pin_design
    from flexctrl.spec.scene import load_scene

    scene_overrides = [o for o in args.set if not o.strip().startswith(CONTROLLER_PREFIX)]
    controller_overrides = [
        o.strip()[len(CONTROLLER_PREFIX) :]
        for o in args.set
        if o.strip().startswith(CONTROLLER_PREFIX)
    ]
    scene = load_scene(args.scene, scene_overrides)
    if scene.kind != "closed_loop":
        raise SpecError(
            f"scene kind '{scene.kind}' runs no controller; allowed: a closed_loop scene",
            source=args.scene,
            key="kind",
        )
    if scene.plant.fidelity.kind == "auto":
        raise SpecError(
            "value 'auto' is not allowed here: the recorded loop needs one plant; allowed: a "
            "fidelity such as 'amm:2' (--set fidelity=\"amm:2\")",
            source=args.scene,
            key="fidelity",
        )
    return build_loop(pin_design(scene), args.controller, tuple(controller_overrides))


def _record(setup, recorder) -> None:
    """The scene's closed loop with every controller step recorded."""
    from flexctrl.loop.sampled import integrate_closed_loop
    from flexctrl.scenes.run_closed_loop_scene import loop_arguments

    recorder.reset()
    integrate_closed_loop(controller=recorder, **loop_arguments(setup), plant_changes=setup.changes)


def _source(setup, args: argparse.Namespace) -> str:
    """The recorded loop in words, for the exported header."""
    plant, scene = setup.plant, setup.plant_scene
    return (
        f"{args.controller} on scene {setup.scene.name} ({args.scene}): plant {plant.name} "
        f"({plant.fidelity}), payload {plant.spec.payload.mass:g} kg, step {scene.dt:g} s, "
        f"{scene.duration:g} s"
    )


def _python_step_times(ctrl, replay, repeats: int) -> dict:
    """Wall time of ``ctrl.step`` over the recorded inputs, ``repeats`` passes (us)."""
    times: list[float] = []
    for _ in range(max(repeats, 1)):
        ctrl.reset()
        for k in range(replay.samples):
            ctrl.u_previous = np.array(replay.u_prev[k])
            start = time.perf_counter()
            ctrl.step(float(replay.t[k]), replay.y[k])
            times.append(time.perf_counter() - start)
    us = np.asarray(times) * 1e6
    return {
        "steps": int(us.size),
        "median_us": float(np.median(us)),
        "p95_us": float(np.percentile(us, 95)),
        "max_us": float(us.max()),
    }


def _times_line(what: str, t: dict) -> str:
    return (
        f"{what}: median {t['median_us']:.2f} us, p95 {t['p95_us']:.2f} us, "
        f"max {t['max_us']:.2f} us over {t['steps']} steps"
    )


def _check(folder: Path, python: dict) -> int:
    """``make -C folder check``; its output, then the C/Python step-time ratio."""
    done = subprocess.run(
        ["make", "-s", "-C", str(folder), "check"], capture_output=True, text=True
    )
    print(done.stdout + done.stderr, end="")
    for line in done.stdout.splitlines():
        if line.startswith("C step time") and python:
            median_c = float(line.split("median ")[1].split(" us")[0])
            print(
                f"median step: C {median_c:.2f} us, Python {python['median_us']:.2f} us, "
                f"Python / C = {python['median_us'] / max(median_c, 1e-3):.0f}"
            )
    return done.returncode
