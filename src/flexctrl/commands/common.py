"""Argument helpers shared by sub-commands (model, payload, configuration, --set, --fidelity)."""

from __future__ import annotations

import argparse
import contextlib
import math
import signal
import threading

import numpy as np

from flexctrl.spec.arm import ArmSpec, load_arm
from flexctrl.spec.fidelity import SPELLINGS, Fidelity, parse_fidelity
from flexctrl.spec.units import warn_if_radians


def add_model_arguments(
    parser: argparse.ArgumentParser, *, fidelity_default: str | None = None
) -> None:
    """Add MODEL, --payload, --q, --set and --fidelity."""
    parser.add_argument(
        "model", metavar="MODEL", help="robot description, e.g. models/subedi3link.toml"
    )
    parser.add_argument(
        "--payload", type=float, metavar="KG", help="payload mass in kg (default: the model file's)"
    )
    parser.add_argument(
        "--q",
        type=float,
        nargs="+",
        metavar="DEG",
        help="joint angles in degrees, one per joint (default: the model file's)",
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override any model-file key, e.g. boundary_inertia=paper (repeatable)",
    )
    parser.add_argument(
        "--fidelity", default=fidelity_default, metavar="F", help=f"model fidelity: {SPELLINGS}"
    )


def load_arm_from_args(args: argparse.Namespace) -> tuple[ArmSpec, np.ndarray]:
    """The validated arm (payload applied) and the configuration in radians.

    ``--q`` values that look like radians warn as the same slip in a file does
    (:func:`flexctrl.spec.units.warn_if_radians`).
    """
    if args.q is not None:
        warn_if_radians(args.q, source=None, key="--q")
    arm = load_arm(args.model, overrides=args.set)
    if args.payload is not None:
        arm = arm.with_payload(args.payload)
    q = arm.configuration_or_default(None if args.q is None else [math.radians(a) for a in args.q])
    return arm, q


def fidelity_from_args(args: argparse.Namespace) -> Fidelity | None:
    """The parsed ``--fidelity`` or None."""
    return None if args.fidelity is None else parse_fidelity(args.fidelity, source="--fidelity")


@contextlib.contextmanager
def stop_signals_interrupt():
    """SIGTERM and SIGINT stop a study or a tuning like Ctrl-C, even when it was started in the
    background.

    A shell starts background jobs with SIGINT ignored, and SIGTERM (``kill``, a batch
    system's time limit) would end Python without running ``finally`` blocks; as a
    KeyboardInterrupt both let the runner write the table and the session's elapsed
    time.  Finished runs are safe either way (each is written atomically).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame):
        raise KeyboardInterrupt(f"signal {signum}")

    previous = {sig: signal.signal(sig, interrupt) for sig in (signal.SIGTERM, signal.SIGINT)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def add_backend_arguments(parser: argparse.ArgumentParser) -> None:
    """Add --workers and --scheduler: where a study's or a tuning's runs go."""
    parser.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="local worker processes (default: the usable CPUs; 0: run in this process)",
    )
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run on a Dask cluster instead, e.g. tcp://127.0.0.1:8786 (needs flexctrl[dask])",
    )
