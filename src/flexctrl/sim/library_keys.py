"""What identifies a compiled library: the C compiler, the host's CPU and the hashed keys.

A library's key hashes what it is built from (a Function's serialized form, or a recipe)
with the flags, the compiler's identity and CasADi's version, and the host's CPU identity
when the flags ask for native code (:data:`NATIVE`), so a changed model, flag, compiler or
machine never reuses a stale library (:mod:`flexctrl.sim.compile`).
"""

from __future__ import annotations

import functools
import hashlib
import os
import platform
import shutil
import subprocess
from collections.abc import Sequence
from typing import Any

import casadi as ca

#: Flags that make code for the host's CPU only (its identity then enters the key).
NATIVE = ("-march=native", "-mcpu=native", "-mtune=native")


def find_compiler() -> str | None:
    """Path of the C compiler: ``$CC``, else ``gcc``, else ``cc``; None when there is none."""
    candidates = [os.environ.get("CC", "").strip(), "gcc", "cc"]
    for name in candidates:
        if name:
            path = shutil.which(name)
            if path:
                return path
    return None


@functools.lru_cache(maxsize=8)
def compiler_identity(compiler: str) -> str:
    """First line of ``compiler --version`` (part of the cache key)."""
    try:
        out = subprocess.run(
            [compiler, "--version"], capture_output=True, text=True, timeout=30, check=False
        )
        return (out.stdout.splitlines() or [""])[0].strip() + f" @ {compiler}"
    except (OSError, subprocess.SubprocessError):
        return compiler


@functools.lru_cache(maxsize=1)
def host_identity() -> str:
    """Machine type and CPU model and feature flags (part of the key for ``-march=native`` code)."""
    parts = [platform.machine(), platform.processor()]
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.startswith(("model name", "flags", "Features")):
                    parts.append(line.strip())
                if len(parts) >= 4:
                    break
    except OSError:
        pass
    return "|".join(parts)


def content_key(*parts: Any) -> str:
    """SHA-256 (hex) of ``parts``: strings as they are, the rest by ``repr``, each NUL-ended.

    Parameters
    ----------
    *parts : object
        What the key is made of.

    Returns
    -------
    str
        64 hexadecimal digits.
    """
    digest = hashlib.sha256()
    for part in parts:
        digest.update((part if isinstance(part, str) else repr(part)).encode())
        digest.update(b"\0")
    return digest.hexdigest()


def cache_key(fun: ca.Function, flags: Sequence[str], compiler: str) -> str:
    """Hash of the Function's serialized form, the flags, the compiler and CasADi's version.

    With ``-march=native`` among the flags the host's CPU identity is hashed too.

    Parameters
    ----------
    fun : casadi.Function
        The Function compiled.
    flags : sequence of str
        The C compiler's flags.
    compiler : str
        Path of the compiler (its identity is hashed).

    Returns
    -------
    str
        As :func:`library_key`.
    """
    return library_key(fun.serialize(), flags, compiler)


def library_key(what: str, flags: Sequence[str], compiler: str) -> str:
    """24 hex digits of ``what`` (a Function's serialized form, or a recipe) with what compiled it.

    The flags, the compiler's identity, CasADi's version, and the host's CPU identity when
    ``-march=native`` is among the flags.

    Parameters
    ----------
    what : str
        A Function's serialized form, or a recipe.
    flags : sequence of str
        The C compiler's flags.
    compiler : str
        Path of the compiler (its identity is hashed).

    Returns
    -------
    str
        24 hexadecimal digits.
    """
    host = host_identity() if any(f.startswith(NATIVE) for f in flags) else ""
    version = ca.__version__  # type: ignore[attr-defined]  # casadi's stubs lack __version__
    return content_key(what, " ".join(flags), compiler_identity(compiler), version, host)[:24]


__all__ = ["NATIVE", "cache_key", "content_key", "find_compiler", "library_key"]
