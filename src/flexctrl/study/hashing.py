"""Stable identities for runs: canonical JSON, short sha256 hashes, derived seeds.

A run is identified by what it computes, not by where it sits in the grid: its
id is the sha256 of the canonical JSON of its settings (keys sorted, no
whitespace, ``-0.0`` written as ``0.0``), cut to :data:`ID_LENGTH` hex digits
(64 bits: a collision among a million runs has odds of about 3e-8).  File
paths enter the identity relative to the study file's folder, so a checkout
can move; the files' contents enter through their sha256 digests, so editing a
controller file gives its runs new ids and a rerun into the same folder does
not reuse stale results.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

ID_LENGTH = 16
PATH_KEYS = ("scene", "model", "controller")


def _normalise(value: Any, where: str = "settings") -> Any:
    if isinstance(value, bool) or value is None or isinstance(value, (str, int)):
        return value
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(
                f"{where}: value {value!r} is not finite; settings must be finite numbers"
            )
        return value + 0.0  # turns -0.0 into 0.0
    if isinstance(value, Mapping):
        out = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise ValueError(f"{where}: key {key!r} is not a string")
            out[key] = _normalise(item, f"{where}.{key}")
        return out
    if isinstance(value, (list, tuple)):
        return [_normalise(item, f"{where}[{i}]") for i, item in enumerate(value)]
    raise ValueError(
        f"{where}: value {value!r} of type {type(value).__name__} is not plain data (JSON)"
    )


def canonical_json(value: Any) -> str:
    """The one JSON spelling of ``value``: sorted keys, no spaces, ``-0.0`` as ``0.0``.

    Raises
    ------
    ValueError
        If ``value`` holds anything that is not plain JSON data or a non-finite float.

    Examples
    --------
    >>> canonical_json({"b": [1, -0.0], "a": "x"})
    '{"a":"x","b":[1,0.0]}'
    """
    return json.dumps(
        _normalise(value), sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False
    )


def short_hash(value: Any, length: int = ID_LENGTH) -> str:
    """The first ``length`` hex digits of the sha256 of :func:`canonical_json` of ``value``."""
    return hashlib.sha256(canonical_json(value).encode()).hexdigest()[:length]


_DIGESTS: dict[tuple[str, int, int], str] = {}


def file_digest(path: str | os.PathLike) -> str:
    """sha256 (hex, 16 digits) of a file's bytes, remembered per (path, mtime, size)."""
    stat = os.stat(path)
    key = (str(Path(path).resolve()), stat.st_mtime_ns, stat.st_size)
    if key not in _DIGESTS:
        _DIGESTS[key] = hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]
    return _DIGESTS[key]


def derive_seed(study_seed: int, key: str) -> int:
    """A 32-bit seed from the study's seed and a run's settings hash.

    The same study gives every run the same seed on every machine and in any
    order; different runs and different study seeds get unrelated seeds.

    Examples
    --------
    >>> derive_seed(1, "abc") == derive_seed(1, "abc") != derive_seed(2, "abc")
    True
    """
    digest = hashlib.sha256(f"flexctrl-seed/{int(study_seed)}/{key}".encode()).digest()
    return int.from_bytes(digest[:4], "big")


def identity(settings: Mapping[str, Any], root: str | os.PathLike) -> dict[str, Any]:
    """``settings`` with the file paths written relative to ``root`` (the study folder).

    The digests of the files are part of the settings already (``settings["digests"]``).
    """
    ident = dict(settings)
    for key in PATH_KEYS:
        value = ident.get(key)
        if isinstance(value, str):
            try:
                ident[key] = Path(os.path.relpath(value, root)).as_posix()
            except ValueError:  # another drive on Windows
                ident[key] = Path(value).as_posix()
    return ident


def run_id(settings: Mapping[str, Any], root: str | os.PathLike) -> str:
    """The id of a run: :func:`short_hash` of its :func:`identity`."""
    return short_hash(identity(settings, root))
