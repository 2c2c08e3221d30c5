"""The exception family of flexctrl, built on the builtins.

Every error a user can cause by their input is a :class:`SpecError` (a
``ValueError``) whose message names the file, the key, the value and what is
allowed, on one line; a valid but doubtful value is a :class:`SpecWarning`
located the same way; a controller designed on a fragile sampled model is a
:class:`DesignWarning`.  Numerical failures are :class:`SimulationError`
(a ``RuntimeError``) or :class:`SolverError`.
"""

from __future__ import annotations

import difflib
import functools
import inspect
import warnings
from collections.abc import Callable
from typing import ParamSpec, TypeVar

_P = ParamSpec("_P")
_R = TypeVar("_R")
_T = TypeVar("_T")


class FlexctrlError(Exception):
    """Base class of every error raised on purpose by flexctrl."""


def _located(message: str, source: str | None, key: str | None) -> str:
    """``"<source>: key '<key>': <message>"`` with the parts that are known."""
    where = [str(source)] if source else []
    if key:
        where.append(f"key '{key}'")
    prefix = ": ".join(where)
    return f"{prefix}: {message}" if prefix else message


class SpecError(FlexctrlError, ValueError):
    """A description (model, scene, controller or study file) is invalid.

    Parameters
    ----------
    message : str
        What is wrong, naming the key, the value and what is allowed.
    source : str, optional
        The file (or other origin) the value came from.
    key : str, optional
        The dotted key of the offending value, e.g. ``links[2].EI``.
    """

    def __init__(self, message: str, *, source: str | None = None, key: str | None = None):
        self.message = message
        self.source = source
        self.key = key
        super().__init__(_located(message, source, key))


class MeasurementError(SpecError):
    """A measurement given to a controller's ``step`` is not finite or has the wrong length.

    Raised before the controller changes any of its state, so the next valid measurement
    gives the torque it would have given had the bad one never been seen.

    Parameters
    ----------
    message
        What is wrong: the channel (``measurement_names[i]``), its value, the sample time.
    channel
        The name of the first offending channel, or None for a wrong length.
    value
        Its value (or the measurement's length for a wrong length).
    t
        The sample time the measurement was given for, s.
    """

    def __init__(
        self,
        message: str,
        *,
        channel: str | None = None,
        value: float | None = None,
        t: float | None = None,
    ):
        self.channel = channel
        self.value = value
        self.t = t
        super().__init__(message, key="measurement")


class SpecWarning(UserWarning):
    """A description is valid but probably not what its author meant (a unit slip, odd value).

    The message names the file, the key, the value and what was expected, on one line,
    as :class:`SpecError`'s does; the command line prints it as one line on stderr.
    """


def warn_spec(
    message: str, *, source: str | None = None, key: str | None = None, stacklevel: int = 3
) -> None:
    """Issue a :class:`SpecWarning` located like a :class:`SpecError` (file, then key)."""
    warnings.warn(_located(message, source, key), SpecWarning, stacklevel=stacklevel)


class DesignWarning(UserWarning):
    """A controller was designed on a model whose sampled form is fragile.

    Issued by :func:`flexctrl.control.design` when the design model has undamped elastic
    modes or a mode within a few percent of a multiple of half the sample rate
    (:mod:`flexctrl.control.sampling_check`); the message is one line naming the modes and
    the sample time.
    """


class SimulationError(FlexctrlError, RuntimeError):
    """An integration failed (divergence, non-finite state, constraint drift)."""


class SolverError(FlexctrlError, RuntimeError):
    """A numerical solver (root finder, QP, NLP, Newton iteration) failed."""


def keyword_checked(fn: Callable[_P, _R]) -> Callable[_P, _R]:
    """``fn`` with a misspelt keyword argument answered by a :class:`TypeError` listing the
    allowed names (and the closest one), as an unknown key in a file is.

    Python's own message names only the unknown keyword.  A function taking ``**kwargs`` is
    returned unchanged.

    >>> @keyword_checked
    ... def move(q, *, duration=1.0, profile="quintic"):
    ...     return q
    >>> try:
    ...     move(0.0, durtion=2.0)
    ... except TypeError as exc:
    ...     print(*str(exc).split("; "), sep="\\n")
    move() got an unexpected keyword argument 'durtion' (did you mean 'duration'?)
    allowed: q, duration, profile
    """
    parameters = inspect.signature(fn).parameters.values()
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters):
        return fn
    allowed = [
        p.name
        for p in parameters
        if p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
        and p.name != "self"
    ]
    title = fn.__qualname__.split(".")[0] if fn.__name__ == "__init__" else fn.__name__

    @functools.wraps(fn)
    def checked(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        for name in kwargs:
            if name not in allowed:
                close = difflib.get_close_matches(name, allowed, n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise TypeError(
                    f"{title}() got an unexpected keyword argument {name!r}{hint}; "
                    f"allowed: {', '.join(allowed)}"
                )
        return fn(*args, **kwargs)

    return checked


def keywords_checked(cls: type[_T]) -> type[_T]:
    """``cls`` (a dataclass) whose constructor answers a misspelt keyword as
    :func:`keyword_checked` does: ``LQRSettings(sample_tim=0.01)`` names ``sample_time``.

    Apply it above ``@dataclass``, so that it wraps the generated ``__init__``.
    """
    cls.__init__ = keyword_checked(cls.__init__)  # type: ignore[method-assign]
    return cls
