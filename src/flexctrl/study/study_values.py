"""Reading a study file's settings: the files it names, the values of its settings and axes.

:class:`ReadContext` holds the reading state (the study file, its folder, the files and
models read so far); the functions check one value each and raise
:class:`~flexctrl.errors.SpecError` naming the study file, the key, the value and what is
allowed.
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from flexctrl.errors import SpecError
from flexctrl.spec import shipped
from flexctrl.spec.fidelity import parse_fidelity
from flexctrl.spec.overrides import apply_overrides
from flexctrl.spec.reader import TableReader, read_toml
from flexctrl.spec.units import warn_if_radians
from flexctrl.study.hashing import canonical_json
from flexctrl.study.plan import FILE_SETTINGS, NO_CONTROLLER, SETTINGS, TARGETS

JOINT = re.compile(r"^q([1-9][0-9]?)$")


class ReadContext:
    """Reading state: the study file, its folder and memoised model loads."""

    def __init__(self, source: str, root: Path):
        self.source = source
        self.root = root
        self._arms: dict[tuple, Any] = {}
        self._docs: dict[str, None] = {}
        self._applied: set[tuple] = set()

    def error(self, key: str, message: str) -> SpecError:
        """A :class:`SpecError` located at ``key`` of the study file."""
        return SpecError(message, source=self.source, key=key)

    def file(self, key: str, value: Any, role: str) -> str | None:
        """An existing, parseable TOML file (absolute path), or None for ``"none"`` controllers."""
        if role == "controller" and value == NO_CONTROLLER:
            return None
        if not isinstance(value, str) or not value:
            raise self.error(
                key,
                f"value {value!r} is not a file path; allowed: a path to a {role} TOML file "
                "relative to the study file" + (" or 'none'" if role == "controller" else ""),
            )
        path = (self.root / value).resolve()
        if not path.is_file():
            try:
                path = shipped.find(
                    value, role if role in shipped.FOLDERS else None, self.root
                ).resolve()
            except SpecError:
                near = ""
                if path.parent.is_dir():
                    hint = difflib.get_close_matches(
                        path.name, [p.name for p in path.parent.glob("*.toml")], n=1
                    )
                    near = f" (did you mean '{hint[0]}'?)" if hint else ""
                raise self.error(
                    key, f"{role} file {value!r} not found (looked at '{path}'){near}"
                ) from None
        if str(path) not in self._docs:
            try:
                read_toml(path)
            except SpecError as exc:
                raise self.error(key, f"{role} file {value!r} is unreadable: {exc}") from None
            self._docs[str(path)] = None
        return str(path)

    def apply(self, key: str, path: str, overrides: tuple[str, ...]) -> None:
        """Check that ``overrides`` apply to the file's document (structure only)."""
        if (path, overrides) not in self._applied:
            try:
                apply_overrides(read_toml(path), overrides, source=path)
            except SpecError as exc:
                raise self.error(key, f"cannot be applied: {exc}") from None
            self._applied.add((path, overrides))

    def arm(self, key: str, model: str, overrides: tuple[str, ...]):
        from flexctrl.spec.arm import load_arm

        cache_key = (model, overrides)
        if cache_key not in self._arms:
            try:
                self._arms[cache_key] = load_arm(model, overrides=overrides)
            except SpecError as exc:
                raise self.error(key, f"model does not load: {exc}") from None
        return self._arms[cache_key]


def setting_value(ctx: ReadContext, key: str, name: str, value: Any) -> Any:
    """Validate one value of a named setting (``payload``, ``scene``, ...)."""
    if name in FILE_SETTINGS:
        return ctx.file(key, value, name)
    if name == "payload":
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not math.isfinite(value)
            or value < 0
        ):
            raise ctx.error(
                key, f"value {value!r} is not allowed; allowed: a finite number >= 0 (kg)"
            )
        return float(value) + 0.0
    if name == "configuration":
        if not isinstance(value, list) or not value:
            raise ctx.error(
                key,
                f"value {value!r} is not a configuration; allowed: a list of joint angles in "
                "degrees, e.g. [0, 90, 0]",
            )
        angles = [_angle(ctx, f"{key}[{i + 1}]", v) for i, v in enumerate(value)]
        warn_if_radians(angles, source=ctx.source, key=key)
        return angles
    if name == "fidelity":
        return str(parse_fidelity(value, source=ctx.source, key=key))
    if JOINT.match(name):
        return _angle(ctx, key, value)
    try:
        canonical_json(value)
    except ValueError:
        raise ctx.error(
            key,
            f"value {value!r} is not plain data; allowed: numbers, strings, booleans, lists, "
            "tables",
        ) from None
    return value


def _angle(ctx: ReadContext, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ctx.error(key, f"value {value!r} is not an angle; allowed: a finite number (degrees)")
    return float(value) + 0.0


def check_override_key(ctx: ReadContext, key: str, name: str) -> None:
    target, _, rest = name.partition(".")
    if target not in TARGETS:
        hint = difflib.get_close_matches(target, TARGETS, n=1)
        extra = f" (did you mean '{hint[0]}.{rest}'?)" if hint else ""
        raise ctx.error(
            key,
            f"'{target}' is not a file to override{extra}; allowed: "
            f"{', '.join(t + '.KEY' for t in TARGETS)}",
        )
    if not rest or any(not part for part in rest.split(".")):
        raise ctx.error(
            key, "override key has an empty part; allowed: scene.KEY, controller.KEY, model.KEY"
        )


def flatten(table: dict, prefix: str = "") -> Iterable[tuple[str, Any]]:
    for name, value in table.items():
        if isinstance(value, dict):
            yield from flatten(value, f"{prefix}{name}.")
        else:
            yield f"{prefix}{name}", value


def unknown_axis(ctx: ReadContext, key: str, name: str) -> SpecError:
    known = list(SETTINGS) + ["q1", "q2", "q3"]
    hint = difflib.get_close_matches(name, known, n=1)
    extra = f"; did you mean '{hint[0]}'?" if hint else ""
    return ctx.error(
        key,
        f"unknown setting{extra} Allowed: {', '.join(SETTINGS)}, q1..qN (one joint, degrees), "
        "scene.KEY, controller.KEY, model.KEY",
    )


def string_list(r: TableReader, name: str, allowed: Sequence[str] | None = None) -> tuple[str, ...]:
    value = r.raw(name)
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise r.error(name, f"value {value!r} is not a list of names")
    if len(set(value)) != len(value):
        raise r.error(name, f"value {value!r} names an entry twice")
    if allowed is not None:
        for item in value:
            if item not in allowed:
                hint = difflib.get_close_matches(item, list(allowed), n=1)
                extra = f" (did you mean '{hint[0]}'?)" if hint else ""
                raise r.error(
                    name,
                    f"'{item}' is not allowed{extra}; allowed: {', '.join(allowed) or '(none)'}",
                )
    return tuple(value)


def nest_dotted_keys(document: dict, source: str) -> dict:
    """``[grid]``/``[set]`` keys written quoted (``"scene.dt" = ...``) as nested tables
    (``scene.dt``).

    Both spellings are allowed in a study file; nesting them first gives one
    spelling, so ``--set grid.scene.dt=[...]`` replaces the file's axis instead
    of adding a second ``scene.dt`` beside it.
    """
    for section in ("grid", "set"):
        table = document.get(section)
        if not isinstance(table, dict):
            continue
        nested: dict[str, Any] = {}
        leaves = {
            key for key, value in table.items() if "." not in key and not isinstance(value, dict)
        }
        for key, value in table.items():
            parts = key.split(".")
            if len(parts) > 1 and parts[0] in leaves:
                # a file axis and an override of that file, e.g. grid.scene = [files] with
                # grid."scene.method" = [...]: TOML cannot nest both, so the override stays quoted
                nested[key] = value
                continue
            node = nested
            for part in parts[:-1]:
                child = node.setdefault(part, {})
                if not isinstance(child, dict):
                    raise SpecError(
                        f"'{key}' clashes with the key '{part}'; allowed: one spelling per setting",
                        source=source,
                        key=f"{section}.{key}",
                    )
                node = child
            if parts[-1] in node:
                raise SpecError(
                    f"'{key}' is given twice (quoted and as a nested table); allowed: one "
                    "spelling per setting",
                    source=source,
                    key=f"{section}.{key}",
                )
            node[parts[-1]] = value
        document[section] = nested
    return document


def spell_like_file(document: dict, assignment: str) -> str:
    """Write a quoted ``--set`` key (``grid."scene.dt"=...``) nested when the file's key is nested.

    A quoted key stays quoted only where :func:`nest_dotted_keys` kept it quoted
    (a file axis beside an override of that file); elsewhere both spellings name the
    same setting.
    """
    key, sep, value = assignment.partition("=")
    if '"' not in key or not sep:
        return assignment
    head, _, rest = key.strip().partition(".")
    table = document.get(head)
    quoted = rest.strip('"')
    if (
        head in ("grid", "set")
        and rest.startswith('"')
        and isinstance(table, dict)
        and quoted not in table
    ):
        return f"{head}.{quoted}={value}"
    return assignment


__all__ = [
    "JOINT",
    "ReadContext",
    "check_override_key",
    "flatten",
    "nest_dotted_keys",
    "spell_like_file",
    "setting_value",
    "string_list",
    "unknown_axis",
]
