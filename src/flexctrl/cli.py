"""The ``flexctrl`` command.

Each sub-command lives in its own module under :mod:`flexctrl.commands` with two
functions, ``add_parser(subparsers)`` and ``run(args) -> int``; this module only
dispatches.  Errors a user can cause (:class:`~flexctrl.errors.SpecError`) are
printed on one line to stderr with exit status 2; numerical failures with
status 3.  Warnings (:class:`~flexctrl.errors.SpecWarning` and any other) are printed
as one line each on stderr, without the source line Python would show.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import warnings
from collections.abc import Sequence

from flexctrl.errors import FlexctrlError, SpecError, SpecWarning

# Sub-command modules, in the order ``flexctrl --help`` lists them.
COMMANDS = (
    "check",
    "modes",
    "modal_report",
    "identify_hubs",
    "linearize",
    "simulate",
    "export",
    "fidelity",
    "bench",
    "study",
    "tune",
    "report",
    "reproduce",
)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every sub-command registered."""
    parser = argparse.ArgumentParser(
        prog="flexctrl",
        description="Control design for robot arms with flexible links. "
        "Units are SI; angles on the command line are in degrees.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        module = importlib.import_module(f"flexctrl.commands.{name}")
        sub = module.add_parser(subparsers)
        sub.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    previous = warnings.formatwarning  # (catch_warnings does not restore it)
    warnings.formatwarning = _one_line_warning(
        args.command
    )  # recording, e.g. by pytest.warns, still works
    try:
        return _run(args)
    finally:
        warnings.formatwarning = previous


def _one_line_warning(command: str):
    """A ``warnings.formatwarning`` giving ``flexctrl COMMAND: warning: MESSAGE`` on one line (no source dump)."""

    def format_warning(message, category, filename, lineno, line=None) -> str:
        text = str(message).replace("\n", " ")
        kind = "" if issubclass(category, SpecWarning) else f"{category.__name__}: "
        return f"flexctrl {command}: warning: {kind}{text}\n"

    return format_warning


def _run(args: argparse.Namespace) -> int:
    try:
        return int(args._run(args) or 0)
    except SpecError as exc:
        print(f"flexctrl {args.command}: error: {exc}".replace("\n", " "), file=sys.stderr)
        return 2
    except FlexctrlError as exc:
        print(f"flexctrl {args.command}: failed: {exc}".replace("\n", " "), file=sys.stderr)
        return 3


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
