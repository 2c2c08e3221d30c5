"""Checks of settings fields, each raising a :class:`~flexctrl.errors.SpecError`.

The error names the key, the value and what is allowed.
"""

from __future__ import annotations

import difflib
import math
from typing import get_args

from flexctrl.errors import SpecError


def choice_field(key: str, value, literal) -> None:
    allowed = get_args(literal)
    if value not in allowed:
        hint = difflib.get_close_matches(str(value), [str(a) for a in allowed], n=1)
        extra = f" (did you mean '{hint[0]}'?)" if hint else ""
        raise SpecError(
            f"value {value!r} is not allowed; allowed: {', '.join(map(repr, allowed))}{extra}",
            key=key,
        )


def number_field(
    key: str,
    value,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    unit: str = "",
) -> None:
    parts = []
    if low is not None:
        parts.append(f"{'>' if low_open else '>='} {low:g}")
    if high is not None:
        parts.append(f"<= {high:g}")
    allowed = (
        "a finite number"
        + (" " + " and ".join(parts) if parts else "")
        + (f" ({unit})" if unit else "")
    )
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SpecError(f"value {value!r} is not a number; allowed: {allowed}", key=key)
    bad = (
        not math.isfinite(value)
        or (low is not None and (value <= low if low_open else value < low))
        or (high is not None and value > high)
    )
    if bad:
        raise SpecError(f"value {value!r} is out of range; allowed: {allowed}", key=key)


def integer_field(key: str, value, *, low: int | None = None, high: int | None = None) -> None:
    allowed = (
        "an integer"
        + (f" from {low}" if low is not None else "")
        + (f" to {high}" if high is not None else "")
    )
    if (
        isinstance(value, bool)
        or not isinstance(value, int)
        or (low is not None and value < low)
        or (high is not None and value > high)
    ):
        raise SpecError(f"value {value!r} is not allowed; allowed: {allowed}", key=key)


def numbers_field(
    key: str, value, *, low: float | None = None, low_open: bool = False, unit: str = ""
) -> None:
    if not isinstance(value, tuple):
        raise SpecError(f"value {value!r} is not a tuple of numbers", key=key)
    for i, v in enumerate(value):
        number_field(f"{key}[{i}]", v, low=low, low_open=low_open, unit=unit)


def boolean_field(key: str, value) -> None:
    if not isinstance(value, bool):
        raise SpecError(f"value {value!r} is not a boolean; allowed: true or false", key=key)
