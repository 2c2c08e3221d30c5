"""Validated reading of TOML tables into plain values.

One :class:`TableReader` wraps one TOML table.  Each accessor checks type,
finiteness and bounds and raises :class:`~flexctrl.errors.SpecError` naming the
file, the dotted key, the value and what is allowed.  :meth:`TableReader.finish`
rejects keys that were never read, with a "did you mean" hint, so a misspelt
key can never be silently ignored.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypeVar

from flexctrl.errors import SpecError
from flexctrl.spec import shipped
from flexctrl.spec.units import warn_if_radians

_MISSING = object()
#: A string type, typically a ``Literal`` of the allowed values (:meth:`TableReader.choice`).
Choice = TypeVar("Choice", bound=str)


def read_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file, turning I/O and syntax errors into :class:`SpecError`.

    A relative path that does not exist is looked up among the shipped files too
    (:func:`flexctrl.spec.shipped.find`).
    """
    path = shipped.find(path, None)
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"not valid TOML: {exc}", source=str(path)) from None


def _describe_bounds(low: float | None, high: float | None, low_open: bool) -> str:
    parts = []
    if low is not None:
        parts.append(f"{'>' if low_open else '>='} {low:g}")
    if high is not None:
        parts.append(f"<= {high:g}")
    return "a finite number " + " and ".join(parts) if parts else "a finite number"


class TableReader:
    """Read and validate the keys of one TOML table.

    Parameters
    ----------
    table
        The parsed table.
    source
        File name used in error messages.
    prefix
        Dotted key prefix of this table (``""`` at the top level).
    """

    def __init__(self, table: Any, source: str, prefix: str = ""):
        if not isinstance(table, dict):
            raise SpecError(
                f"expected a table, got {type(table).__name__} {table!r}",
                source=source,
                key=prefix or None,
            )
        self.table = table
        self.source = source
        self.prefix = prefix
        self._seen: set[str] = set()
        self._known: set[str] = set()  # names asked about (has) but maybe absent: for hints

    # -- helpers ---------------------------------------------------------------
    def key(self, name: str) -> str:
        """The dotted key of ``name`` inside this table."""
        return f"{self.prefix}.{name}" if self.prefix else name

    def error(self, name: str, message: str) -> SpecError:
        """A :class:`SpecError` about key ``name`` of this table."""
        return SpecError(message, source=self.source, key=self.key(name))

    def has(self, name: str) -> bool:
        """Whether the table holds ``name`` (which becomes a known key of the suggestions)."""
        self._known.add(name)
        return name in self.table

    def accept(self, *names: str) -> None:
        """Mark ``names`` as keys of this table that another reader handles (never unknown)."""
        self._seen.update(names)

    def raw(self, name: str, default: Any = _MISSING, *, allowed: str = "") -> Any:
        """The unvalidated value of ``name`` (marks it as read).

        ``allowed`` describes it in the error when it is missing.
        """
        self._seen.add(name)
        if name not in self.table:
            if default is _MISSING:
                close = difflib.get_close_matches(
                    name, [k for k in self.table if k not in self._seen], n=1
                )
                hint = f" (found '{self.key(close[0])}': did you mean '{name}'?)" if close else ""
                raise self.error(
                    name,
                    f"missing required key{hint}" + (f"; allowed: {allowed}" if allowed else ""),
                )
            return default
        return self.table[name]

    # -- typed accessors ---------------------------------------------------------
    def number(
        self,
        name: str,
        default: Any = _MISSING,
        *,
        low: float | None = None,
        high: float | None = None,
        low_open: bool = False,
        unit: str = "",
    ) -> float:
        """A finite float within ``[low, high]`` (``(low, high]`` if ``low_open``)."""
        value = self.raw(
            name,
            default,
            allowed=_describe_bounds(low, high, low_open) + (f" ({unit})" if unit else ""),
        )
        return self.check_number(name, value, low=low, high=high, low_open=low_open, unit=unit)

    def check_number(
        self,
        name: str,
        value: Any,
        *,
        low: float | None = None,
        high: float | None = None,
        low_open: bool = False,
        unit: str = "",
    ) -> float:
        """Validate ``value`` as a number for key ``name`` (see :meth:`number`)."""
        allowed = _describe_bounds(low, high, low_open) + (f" ({unit})" if unit else "")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(name, f"value {value!r} is not a number; allowed: {allowed}")
        value = float(value)
        bad = (
            not math.isfinite(value)
            or (low is not None and (value <= low if low_open else value < low))
            or (high is not None and value > high)
        )
        if bad:
            raise self.error(name, f"value {value!r} is out of range; allowed: {allowed}")
        return value

    def positive(self, name: str, default: Any = _MISSING, *, unit: str = "") -> float:
        """A finite number > 0."""
        return self.number(name, default, low=0.0, low_open=True, unit=unit)

    def nonnegative(self, name: str, default: Any = _MISSING, *, unit: str = "") -> float:
        """A finite number >= 0."""
        return self.number(name, default, low=0.0, unit=unit)

    def integer(
        self, name: str, default: Any = _MISSING, *, low: int | None = None, high: int | None = None
    ) -> int:
        """An integer within ``[low, high]``."""
        allowed = (
            "an integer"
            + (f" from {low}" if low is not None else "")
            + (f" to {high}" if high is not None else "")
        )
        value = self.raw(name, default, allowed=allowed)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(name, f"value {value!r} is not an integer; allowed: {allowed}")
        if (low is not None and value < low) or (high is not None and value > high):
            raise self.error(name, f"value {value!r} is out of range; allowed: {allowed}")
        return value

    def boolean(self, name: str, default: Any = _MISSING) -> bool:
        """``true`` or ``false``."""
        value = self.raw(name, default, allowed="true or false")
        if not isinstance(value, bool):
            raise self.error(name, f"value {value!r} is not a boolean; allowed: true or false")
        return value

    def string(
        self, name: str, default: Any = _MISSING, *, choices: Sequence[str] | None = None
    ) -> str:
        """A string, optionally one of ``choices``."""
        allowed = ", ".join(map(repr, choices)) if choices is not None else "a string"
        value = self.raw(name, default, allowed=allowed)
        if not isinstance(value, str):
            raise self.error(name, f"value {value!r} is not a string; allowed: {allowed}")
        if choices is not None and value not in choices:
            hint = difflib.get_close_matches(value, list(choices), n=1)
            extra = f" (did you mean '{hint[0]}'?)" if hint else ""
            raise self.error(
                name,
                f"value {value!r} is not allowed; allowed: {', '.join(map(repr, choices))}{extra}",
            )
        return value

    def choice(self, name: str, choices: Sequence[Choice], default: Any = _MISSING) -> Choice:
        """One of ``choices`` (typed as they are: a ``Literal`` stays a ``Literal``)."""
        value = self.string(name, default, choices=choices)
        return next(c for c in choices if c == value)

    def numbers(
        self,
        name: str,
        default: Any = _MISSING,
        *,
        length: int | None = None,
        low: float | None = None,
        high: float | None = None,
        low_open: bool = False,
        unit: str = "",
    ) -> tuple[float, ...]:
        """A list of finite numbers, each within bounds, optionally of fixed length."""
        allowed = (
            (f"a list of {length}" if length is not None else "a list of")
            + " "
            + _describe_bounds(low, high, low_open).replace("a finite number", "finite numbers")
            + (f" ({unit})" if unit else "")
        )
        value = self.raw(name, default, allowed=allowed)
        if not isinstance(value, (list, tuple)):
            raise self.error(name, f"value {value!r} is not a list of numbers; allowed: {allowed}")
        if length is not None and len(value) != length:
            raise self.error(
                name, f"value {value!r} has {len(value)} entries; allowed: exactly {length}"
            )
        return tuple(
            self.check_number(f"{name}[{i}]", v, low=low, high=high, low_open=low_open, unit=unit)
            for i, v in enumerate(value)
        )

    def degrees(
        self, name: str, default: Any = _MISSING, *, length: int | None = None
    ) -> tuple[float, ...]:
        """Joint angles in degrees (a list); warns when they look like radians.

        The check is :mod:`flexctrl.spec.units`'.
        """
        values = self.numbers(name, default, length=length, unit="degrees")
        if self.has(name):
            warn_if_radians(values, source=self.source, key=self.key(name))
        return values

    def degree(self, name: str, default: Any = _MISSING) -> float:
        """One angle in degrees; warns when it looks like radians."""
        value = self.number(name, default, unit="degrees")
        if self.has(name):
            warn_if_radians([value], source=self.source, key=self.key(name))
        return value

    def table_of(self, name: str, default: Any = _MISSING) -> TableReader:
        """The sub-table ``name`` as a reader."""
        value = self.raw(name, default, allowed=f"a table [{self.key(name)}]")
        return TableReader(value, self.source, self.key(name))

    def tables(self, name: str, *, min_count: int = 0) -> list[TableReader]:
        """An array of tables (``[[name]]``) as readers."""
        value = self.raw(name, allowed=f"one or more [[{self.key(name)}]] tables")
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.error(name, f"expected an array of tables ([[{name}]]), got {value!r}")
        if len(value) < min_count:
            raise self.error(name, f"has {len(value)} entries; allowed: at least {min_count}")
        return [
            TableReader(v, self.source, f"{self.key(name)}[{i + 1}]") for i, v in enumerate(value)
        ]

    def finish(self) -> None:
        """Reject every key of the table that was not read, with a suggestion."""
        unknown = [k for k in self.table if k not in self._seen]
        if unknown:
            name = unknown[0]
            names = sorted(self._seen | self._known)
            hint = difflib.get_close_matches(name, names, n=1)
            extra = f"; did you mean '{hint[0]}'?" if hint else ""
            known = ", ".join(names)
            raise self.error(
                name,
                f"unknown key (value {self.table[name]!r}){extra} Allowed: the known keys here: "
                f"{known}",
            )
