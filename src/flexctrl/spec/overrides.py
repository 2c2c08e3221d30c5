"""``--set KEY=VALUE`` overrides applied to a parsed TOML document.

Keys are dotted paths; array-of-table entries are addressed 1-based, either as
``links[2].EI`` or ``links.2.EI``.  A part written in double quotes is one key even
if it holds dots, as in TOML: ``grid."scene.method"``.  Values are parsed as TOML values
(``2``, ``1e-4``, ``true``, ``[0, 90, 0]``, ``"paper"``); anything that is not a
TOML value is taken as a plain string, so ``boundary_inertia=paper`` works.
The overridden document then goes through the same validation as the file.
"""

from __future__ import annotations

import copy
import re
import tomllib
from collections.abc import Iterable, Mapping
from typing import Any

from flexctrl.errors import SpecError

_INDEX = re.compile(r"^(?P<name>[^\[\]]+)\[(?P<index>\d+)\]$")


def parse_value(text: str) -> Any:
    """Parse ``text`` as a TOML value, falling back to the plain string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _pieces(key: str, source: str) -> list[tuple[str, bool]]:
    """Split ``key`` on the dots outside double quotes: (piece, was_quoted) pairs."""
    pieces, current, quoted, inside = [], "", False, False
    for char in key:
        if char == '"':
            inside, quoted = not inside, True
        elif char == "." and not inside:
            pieces.append((current, quoted))
            current, quoted = "", False
        else:
            current += char
    if inside:
        raise SpecError(
            f"override key '{key}' has an unclosed quote; allowed: a key part in double quotes, "
            'e.g. grid."scene.dt"',
            source=source,
        )
    pieces.append((current, quoted))
    return pieces


def _split_key(key: str, source: str = "--set") -> list[str | int]:
    parts: list[str | int] = []
    for piece, quoted in _pieces(key, source):
        if quoted and piece:
            parts.append(piece)
            continue
        match = _INDEX.match(piece)
        if match:
            parts += [match["name"], int(match["index"])]
        elif piece.isdigit():
            parts.append(int(piece))
        elif piece:
            parts.append(piece)
        else:
            raise SpecError(f"override key '{key}' has an empty part", source=source)
    return parts


def apply_overrides(
    document: dict[str, Any], assignments: Iterable[str], source: str = "--set"
) -> dict[str, Any]:
    """Return a copy of ``document`` with ``KEY=VALUE`` assignments applied.

    Parameters
    ----------
    document
        Parsed TOML document (not modified).
    assignments
        Strings ``"KEY=VALUE"``.
    source
        Name used in error messages.

    Raises
    ------
    SpecError
        If an assignment has no ``=`` or addresses a list entry that does not exist.
    """
    result = copy.deepcopy(document)
    for assignment in assignments:
        if "=" not in assignment:
            raise SpecError(f"'{assignment}' is not of the form KEY=VALUE", source=source)
        key, text = assignment.split("=", 1)
        _assign(result, key.strip(), parse_value(text.strip()), source)
    return result


def apply_values(
    document: dict[str, Any], values: Mapping[str, Any], source: str = "overrides"
) -> dict[str, Any]:
    """A copy of ``document`` with ``{KEY: value}`` set, the keys spelled as for ``--set``.

    The values are used as given (Python numbers, lists, strings), not parsed, so the
    document's validation sees exactly what the caller passed: ``{"payload.mass": "0.5"}``
    is refused by the reader as a string where a number belongs.

    Examples
    --------
    >>> apply_values({"links": [{"EI": 1.0}]}, {"links[1].EI": 2.0})
    {'links': [{'EI': 2.0}]}
    """
    result = copy.deepcopy(document)
    for key, value in values.items():
        if not isinstance(key, str) or not key.strip():
            raise SpecError(
                f"override key {key!r} is not allowed; allowed: a dotted key such as 'links[1].EI'",
                source=source,
            )
        _assign(result, key.strip(), copy.deepcopy(value), source)
    return result


def _assign(result: dict[str, Any], key: str, value: Any, source: str) -> None:
    parts = _split_key(key, source)
    node: Any = result
    for depth, part in enumerate(parts[:-1]):
        node = _descend(node, part, key, source, create=not isinstance(parts[depth + 1], int))
    last = parts[-1]
    if isinstance(last, int):
        if not isinstance(node, list) or not 1 <= last <= len(node):
            raise SpecError(f"index {last} does not exist (1-based)", source=source, key=key)
        node[last - 1] = value
    else:
        if not isinstance(node, dict):
            raise SpecError(f"'{last}' is not inside a table", source=source, key=key)
        node[last] = value


def _descend(node: Any, part: str | int, key: str, source: str, create: bool) -> Any:
    if isinstance(part, int):
        if not isinstance(node, list) or not 1 <= part <= len(node):
            raise SpecError(f"index {part} does not exist (1-based)", source=source, key=key)
        return node[part - 1]
    if not isinstance(node, dict):
        raise SpecError(f"'{part}' is not inside a table", source=source, key=key)
    if part not in node:
        if not create:
            raise SpecError(f"'{part}' does not exist", source=source, key=key)
        node[part] = {}
    return node[part]
