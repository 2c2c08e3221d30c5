"""The ``flexctrl`` command.

Each sub-command lives in its own module under :mod:`flexctrl.commands` with two
functions, ``add_parser(subparsers)`` and ``run(args) -> int``; this module only
dispatches.  Errors a user can cause (:class:`~flexctrl.errors.SpecError`) are
printed on one line to stderr with exit status 2; numerical failures with
status 3.  Ctrl-C ends a command with one line (with the module's
``interrupt_hint(args)``, if it has one, saying how to pick up) and status 130; a closed
output pipe (``flexctrl modes ... | head``) ends it quietly with status 141, as SIGPIPE
would.  Warnings (:class:`~flexctrl.errors.SpecWarning` and any other) are printed
as one line each on stderr, without the source line Python would show.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from collections.abc import Callable, Sequence
from types import ModuleType

from flexctrl.commands import (
    bench,
    check,
    examples,
    export,
    fidelity,
    identify_hubs,
    linearize,
    modal_report,
    modes,
    report,
    reproduce,
    simulate,
    study,
    tune,
)
from flexctrl.errors import FlexctrlError, SpecError, SpecWarning

#: Sub-command modules, in the order ``flexctrl --help`` lists them.  Each imports only light
#: modules at its top (the heavy ones inside ``run``), so building the parser stays quick.
COMMANDS: tuple[ModuleType, ...] = (
    examples,
    check,
    modes,
    modal_report,
    identify_hubs,
    linearize,
    simulate,
    export,
    fidelity,
    bench,
    study,
    tune,
    report,
    reproduce,
)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every sub-command registered."""
    parser = argparse.ArgumentParser(
        prog="flexctrl",
        description="Control design for robot arms with flexible links. "
        "Units are SI; angles on the command line are in degrees.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in COMMANDS:
        sub = module.add_parser(subparsers)
        sub.set_defaults(_run=module.run, _hint=getattr(module, "interrupt_hint", None))
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    # catch_warnings does not restore formatwarning; recording (pytest.warns) still works
    previous = warnings.formatwarning
    warnings.formatwarning = _one_line_warning(args.command)
    try:
        return _run(args)
    finally:
        warnings.formatwarning = previous


def _one_line_warning(command: str) -> Callable[..., str]:
    """A ``warnings.formatwarning`` giving ``flexctrl COMMAND: warning: MESSAGE`` on one line,
    without the source line."""

    def format_warning(
        message: Warning | str,
        category: type[Warning],
        filename: str,
        lineno: int,
        line: str | None = None,
    ) -> str:
        text = str(message).replace("\n", " ")
        kind = "" if issubclass(category, SpecWarning) else f"{category.__name__}: "
        return f"flexctrl {command}: warning: {kind}{text}\n"

    return format_warning


def _run(args: argparse.Namespace) -> int:
    try:
        status = int(args._run(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, inside the handlers below
        return status
    except SpecError as exc:
        print(f"flexctrl {args.command}: error: {exc}".replace("\n", " "), file=sys.stderr)
        return 2
    except FlexctrlError as exc:
        print(f"flexctrl {args.command}: failed: {exc}".replace("\n", " "), file=sys.stderr)
        return 3
    except KeyboardInterrupt:
        hint = args._hint(args) if args._hint is not None else ""
        print(f"flexctrl {args.command}: interrupted{'; ' + hint if hint else ''}", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader left (``| head``): send what is still buffered nowhere, so the flush at
        # exit does not raise again
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
