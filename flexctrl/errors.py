"""The exception family of flexctrl, built on the builtins.

Every error a user can cause by their input is a :class:`SpecError` (a
``ValueError``) whose message names the file, the key, the value and what is
allowed, on one line.  Numerical failures are :class:`SimulationError`
(a ``RuntimeError``) or :class:`SolverError`.
"""

from __future__ import annotations


class FlexctrlError(Exception):
    """Base class of every error raised on purpose by flexctrl."""


class SpecError(FlexctrlError, ValueError):
    """A description (model, scene, controller or study file) is invalid.

    Parameters
    ----------
    message
        What is wrong, naming the key, the value and what is allowed.
    source
        The file (or other origin) the value came from.
    key
        The dotted key of the offending value, e.g. ``links[2].EI``.
    """

    def __init__(self, message: str, *, source: str | None = None, key: str | None = None):
        self.source = source
        self.key = key
        where = []
        if source:
            where.append(str(source))
        if key:
            where.append(f"key '{key}'")
        prefix = ": ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)


class SimulationError(FlexctrlError, RuntimeError):
    """An integration failed (divergence, non-finite state, constraint drift)."""


class SolverError(FlexctrlError, RuntimeError):
    """A numerical solver (root finder, QP, NLP, Newton iteration) failed."""
