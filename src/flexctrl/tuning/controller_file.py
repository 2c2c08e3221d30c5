"""A controller file with new values for some keys, its comments and layout kept.

Each key is a dotted path (``weights.joint_deg``, ``sensors.noise.joints_deg``,
``horizon``).  The value is replaced where the file writes the key: on its own line
(``joint_deg = 0.5  # deg``) in its table, or inside an inline table of that table
(``noise = { joints_deg = 0.005, strain = 1e-4 }``).  A key the file leaves at its
default is added under its table's header (the table is appended if the file has none).
The result is read back and compared with the original document with the values set:
any difference is an error, never a silently wrong file.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from flexctrl.errors import SpecError
from flexctrl.spec.overrides import apply_values
from flexctrl.study.plan import toml_literal

_HEADER = re.compile(r"^\s*\[([^\[\]]+)\]\s*(#.*)?$")
_VALUE = r"[-+0-9.eEinfa_]+|true|false|\"[^\"]*\""


def with_values(
    text: str, values: Mapping[str, Any], *, header: str = "", source: str = "controller file"
) -> str:
    """``text`` (a TOML controller file) with ``values`` set (key -> value), ``header`` comment
    lines first.

    Raises
    ------
    SpecError
        When a key cannot be placed (an array of tables, a value spread over lines) or
        the written file does not read back as intended.
    """
    lines = text.splitlines()
    while (
        header and lines and lines[0].startswith("# Tuned by ")
    ):  # a re-tuned file names its last tuning only
        lines = lines[1:]
    for key, value in values.items():
        lines = _set(lines, key, toml_literal(value), source)
    out = "\n".join(lines) + "\n"
    if header:
        out = "".join(f"# {line}\n" if line else "#\n" for line in header.splitlines()) + out
    expected = apply_values(tomllib.loads(text), dict(values), source=source)
    written: dict[str, Any] | tomllib.TOMLDecodeError
    try:
        written = tomllib.loads(out)
    except tomllib.TOMLDecodeError as exc:
        written = exc
    if written != expected:
        why = written if isinstance(written, Exception) else "it reads back differently"
        raise SpecError(
            f"the tuned values {dict(values)!r} could not be written into the file as intended "
            f"({why}); "
            "allowed: keys written on their own lines or in one-line inline tables of plain "
            "[table] "
            "headers",
            source=source,
        )
    return out


def write_controller(
    original: Path, values: Mapping[str, Any], destination: Path, header: str
) -> Path:
    """Write ``original`` with ``values`` set to ``destination`` (see :func:`with_values`)."""
    text = with_values(Path(original).read_text(), values, header=header, source=str(original))
    destination.parent.mkdir(parents=True, exist_ok=True)
    destination.write_text(text)
    return destination


def _line_tables(lines: list[str]) -> list[str | None]:
    """The table each line belongs to (``""`` before the first header, ``"[[array]]"`` inside arrays
    of
    tables, None for a header line itself): one scan, shared by every search below."""
    owners: list[str | None] = []
    current = ""
    for line in lines:
        match = _HEADER.match(line)
        if match or line.lstrip().startswith("[["):
            current = match.group(1).strip() if match else "[[array]]"
            owners.append(None)
        else:
            owners.append(current)
    return owners


def _replaced(lines: list[str], i: int, line: str) -> list[str]:
    out = list(lines)
    out[i] = line
    return out


def _set(lines: list[str], key: str, literal: str, source: str) -> list[str]:
    parts = key.split(".")
    table, leaf = ".".join(parts[:-1]), parts[-1]
    element = re.fullmatch(r"(\w+)\[(\d+)\]", leaf)
    if element:
        return _set_element(lines, table, element.group(1), int(element.group(2)), literal, source)
    owner, _, name = table.rpartition(
        "."
    )  # the key may sit in the inline table `name` of table `owner`
    owners = _line_tables(lines)
    for i, line in enumerate(lines):  # written on its own line in its table
        if owners[i] == table:
            replaced, count = re.subn(
                rf"^(\s*{re.escape(leaf)}\s*=\s*)({_VALUE})", lambda m: m.group(1) + literal, line
            )
            if count:
                return _replaced(lines, i, replaced)
    inline = [
        i
        for i, line in enumerate(lines)
        if name and owners[i] == owner and re.match(rf"^\s*{re.escape(name)}\s*=\s*\{{", line)
    ]
    for i in inline:  # written inside a one-line inline table
        replaced, count = re.subn(
            rf"([{{,]\s*{re.escape(leaf)}\s*=\s*)({_VALUE})",
            lambda m: m.group(1) + literal,
            lines[i],
        )
        if count:
            return _replaced(lines, i, replaced)
    for i in inline:  # missing from an existing inline table: added inside its braces
        found = re.match(r"^(.*?=\s*\{)([^}]*)(\}.*)$", lines[i])
        if found:
            inside = found.group(2).rstrip()
            sep = ", " if inside.strip() else " "
            return _replaced(
                lines, i, f"{found.group(1)}{inside}{sep}{leaf} = {literal} {found.group(3)}"
            )
    rows = [i for i, o in enumerate(owners) if o == table]
    header = [
        i
        for i, line in enumerate(lines)
        if owners[i] is None and (m := _HEADER.match(line)) and m.group(1).strip() == table
    ]
    if (
        table == "" or header
    ):  # the table exists and does not write the key: add it at the table's end
        end = (rows[-1] + 1) if rows else (header[0] + 1 if header else 0)
        start = header[0] + 1 if header else 0
        while end > start and not lines[end - 1].strip():
            end -= 1
        return lines[:end] + [f"{leaf} = {literal}"] + lines[end:]
    return lines + ["", f"[{table}]", f"{leaf} = {literal}"]


def _set_element(
    lines: list[str], table: str, name: str, index: int, literal: str, source: str
) -> list[str]:
    """Entry ``index`` (1-based) of the one-line array ``name = [...]`` in ``table``."""
    owners = _line_tables(lines)
    for i, line in enumerate(lines):
        found = re.match(rf"^(\s*{re.escape(name)}\s*=\s*)(\[[^\]]*\])(.*)$", line)
        if owners[i] == table and found:
            values = tomllib.loads(f"v = {found.group(2)}")["v"]
            if not 1 <= index <= len(values):
                break
            values[index - 1] = tomllib.loads(f"v = {literal}")["v"]
            return _replaced(lines, i, found.group(1) + toml_literal(values) + found.group(3))
    raise SpecError(
        f"key '{table + '.' if table else ''}{name}[{index}]': the file has no one-line array "
        f"'{name}' with "
        f"that entry; allowed: write the array in the file first",
        source=source,
    )
