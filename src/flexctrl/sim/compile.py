"""Compile CasADi Functions to shared libraries, cached on disk, with a virtual-machine fall-back.

:func:`compile_function` generates C code for a Function (``casadi.CodeGenerator``),
compiles it with the system C compiler (``$CC``, else ``gcc``, else ``cc``) into
``<name>_<key>.so`` and loads it with ``casadi.external``.  ``key`` is a hash of
the Function's serialized form, the compiler flags, the compiler's identity and
the CasADi version, so a changed model, flag or compiler never reuses a stale
library.  Libraries live in the user cache folder (:mod:`flexctrl.user_cache`); they
are written under a temporary name and renamed into place, so concurrent runs
sharing a cache never load a half-written file.

A shared library runs with the rights of whoever loads it, so the cache is trusted only
when it is the user's alone: the folder is created owner-only (mode 0700), and a library
is loaded only if it is a regular file the user owns that nobody else may write
(:func:`~flexctrl.user_cache.trusted_file`); any other is rebuilt in its place.  A cache
folder that another user owns, or that others may write, is not used at all: libraries then
go to a private temporary folder for this process (with a warning saying why).

When no compiler is found, compilation fails, ``compile=False`` is passed or the
environment variable ``FLEXCTRL_NO_COMPILE`` is set to anything but ``""``/``"0"``,
the Function itself is returned and CasADi's virtual machine evaluates it
(a warning says why when a compiler was expected but failed).

Flags: ``-O2 -march=native`` by default, for the Functions evaluated at every step (the
integrators' loops, the closed loop's plant step).  ``-march=native`` lets the compiler use
the host's vector and fused multiply-add instructions; such code only runs on the CPU it was
built for, so the cache key includes the host's CPU identity, and if the compiler rejects
the flags the portable ``-O2`` is tried before giving up.  :data:`QUICK_FLAGS` serve large
Functions evaluated in bulk a few times per run, where the compile time dominates.

:func:`compile_by_recipe` finds a library without building its Function: for a Function whose
symbolic construction costs more than loading it (the NMPC's horizon linearisation), the
caller names everything the construction depends on (a *recipe*: its inputs' serialized
forms and the source of the code that builds it), and the first build leaves a hard link
``<name>_r<key>.so`` to the library, ``key`` hashing the recipe with the flags, compiler,
CasADi version and host as above.

:func:`compile_for` keeps a compiled Function with the object it was built from (a lifted
Function kept per model structure): the next model of that structure gets it without building
it, serializing it for its key or loading the library again.
"""

from __future__ import annotations

import logging
import os
import shutil
import subprocess
import tempfile
import time
import uuid
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca

from flexctrl.dynamics.parametric import FROM_LIFTED
from flexctrl.sim.library_keys import NATIVE, cache_key, content_key, find_compiler, library_key
from flexctrl.user_cache import cache_directory, private_directory, trusted_file

log = logging.getLogger(__name__)

ENV_NO_COMPILE = "FLEXCTRL_NO_COMPILE"
DEFAULT_FLAGS: tuple[str, ...] = ("-O2", "-march=native")
PORTABLE_FLAGS: tuple[str, ...] = ("-O2",)
#: For large Functions evaluated in bulk a few times per run rather than per step (the reference
#: tables' Newton): GCC's ``-Og`` runs the cheap optimisations of ``-O1`` without the costly
#: register allocation over one huge function body, so a generated file of tens of thousands of
#: lines compiles in seconds instead of tens of seconds and evaluates as fast.
QUICK_FLAGS: tuple[str, ...] = ("-Og", "-march=native")
COMPILE_TIMEOUT_S = 900.0


@dataclass(frozen=True)
class CompiledFunction:
    """The outcome of :func:`compile_function`.

    Attributes
    ----------
    function : casadi.Function
        The compiled external, or the original Function (virtual machine).
    compiled : bool
        True when ``function`` runs from a shared library.
    cache_hit : bool
        True when the library was found in the cache (nothing was compiled).
    path : pathlib.Path or None
        The shared library.
    compile_seconds : float
        Time spent generating and compiling (0 on a cache hit).
    reason : str
        Why the virtual machine is used, or ``""``.
    flags : tuple of str
        The compiler flags the library was built with.
    """

    function: ca.Function
    compiled: bool
    cache_hit: bool = False
    path: Path | None = None
    compile_seconds: float = 0.0
    reason: str = ""
    flags: tuple[str, ...] = ()


def compile_disabled_by_env() -> bool:
    """Whether ``FLEXCTRL_NO_COMPILE`` asks for the virtual machine."""
    return os.environ.get(ENV_NO_COMPILE, "").strip() not in ("", "0")


def compile_function(
    fun: ca.Function,
    *,
    enabled: bool | None = None,
    cache_dir: str | os.PathLike | None = None,
    flags: Sequence[str] = DEFAULT_FLAGS,
) -> CompiledFunction:
    """Compile ``fun`` to a cached shared library, or fall back to the virtual machine.

    Parameters
    ----------
    fun
        Any CasADi Function that supports code generation.
    enabled
        ``False`` forces the virtual machine; ``None`` (default) compiles unless
        ``FLEXCTRL_NO_COMPILE`` is set.
    cache_dir
        Where libraries are kept (default: :func:`cache_directory`).
    flags
        Compiler flags (``-shared -fPIC`` are always added).

    Returns
    -------
    CompiledFunction
    """
    if enabled is None:
        enabled = not compile_disabled_by_env()
    if not enabled:
        return CompiledFunction(fun, compiled=False, reason="compilation switched off")
    compiler = find_compiler()
    if compiler is None:
        return CompiledFunction(fun, compiled=False, reason="no C compiler found ($CC, gcc, cc)")
    flags = tuple(flags)
    directory = private_directory(cache_directory(cache_dir))
    portable = tuple(
        f for f in flags if f not in NATIVE
    )  # a compiler without -march=native gets a second try
    attempts = [flags] + ([portable] if portable != flags else [])
    failure = ""
    for attempt in attempts:
        result = _compile_or_load(fun, directory, compiler, attempt)
        if isinstance(result, CompiledFunction):
            return result
        failure = result
    message = (
        f"compiling '{fun.name()}' with {compiler} failed ({failure}); using CasADi's virtual "
        "machine"
    )
    warnings.warn(message, stacklevel=2)
    return CompiledFunction(fun, compiled=False, reason=message)


def compile_by_recipe(
    name: str,
    recipe: str,
    build: Callable[[], ca.Function],
    *,
    enabled: bool | None = None,
    cache_dir: str | os.PathLike | None = None,
    flags: Sequence[str] = DEFAULT_FLAGS,
    check: Callable[[ca.Function], bool] | None = None,
) -> CompiledFunction:
    """The library of ``build()``'s Function, found by ``recipe`` without calling ``build``.

    Parameters
    ----------
    name
        The name of the Function ``build`` returns (the library's symbol).
    recipe
        A string naming everything ``build()`` depends on: its inputs (serialized) and the
        source text of the code that builds it.  A recipe that leaves out something the
        Function depends on loads a stale library: that is the caller's contract.
    build
        Makes the Function (called only when no library is found by the recipe).
    enabled, cache_dir, flags
        As for :func:`compile_function`.
    check
        Applied to a library found by the recipe (the caller's comparison with what it
        should compute); one that fails it, or raises, is unlinked with a warning and the
        Function is built.

    Returns
    -------
    CompiledFunction
        ``cache_hit`` True, ``path`` the recipe's link, when found by the recipe; otherwise
        what :func:`compile_function` returns for ``build()``, after linking its library
        under the recipe's name (only for the flags asked for, not the portable fall-back).
        Deleting a library to force its rebuild means deleting its ``<name>_r*.so`` links too.
    """
    if enabled is None:
        enabled = not compile_disabled_by_env()
    compiler = find_compiler() if enabled else None
    if compiler is None:
        return compile_function(build(), enabled=enabled, cache_dir=cache_dir, flags=flags)
    flags = tuple(flags)
    directory = private_directory(cache_directory(cache_dir))
    link = directory / f"{name}_r{library_key(recipe, flags, compiler)}.so"
    found = _load_link(name, link, flags, check)
    if found is not None:
        return found
    fun = build()
    if fun.name() != name:
        raise ValueError(f"compile_by_recipe: build() made '{fun.name()}', not '{name}'")
    result = compile_function(fun, enabled=True, cache_dir=cache_dir, flags=flags)
    if result.compiled and result.path is not None and tuple(result.flags) == flags:
        _link(result.path, link)
    return result


def _load_link(name: str, link: Path, flags: tuple[str, ...], check) -> CompiledFunction | None:
    """The library at ``link`` if it is trusted, loads and passes ``check``; otherwise None.

    A library that fails ``check`` (or makes it raise) is unlinked, with a warning.
    """
    if not (link.is_file() and trusted_file(link)):
        return None
    try:
        function = ca.external(name, str(link))
    except RuntimeError as exc:  # unreadable: build it again
        log.warning("library %s could not be loaded (%s); building %s again", link, exc, name)
        return None
    try:
        passed = check is None or check(function)
    except RuntimeError as exc:  # another signature: not this recipe's Function
        passed, why = False, f" (the check raised: {exc})"
    else:
        why = ""
    if passed:
        return CompiledFunction(function, compiled=True, cache_hit=True, path=link, flags=flags)
    warnings.warn(
        f"the library {link} found by its recipe does not reproduce what it should{why}; "
        f"removed and built again",
        stacklevel=3,
    )
    link.unlink(missing_ok=True)
    return None


def _link(library: Path, link: Path) -> None:
    """``link`` made a hard link to ``library`` (a copy where the file system has none), atomically.

    A failure is logged, not raised: the library is fine, only the next process's shortcut is lost.
    """
    temporary = link.with_name(f"{link.name}.{uuid.uuid4().hex}.tmp")
    try:
        try:
            os.link(library, temporary)
        except OSError:  # a file system without hard links
            shutil.copy2(library, temporary)
        os.replace(temporary, link)
    except OSError as exc:
        log.warning(
            "could not link %s as %s (%s); the next process builds it again", library, link, exc
        )
        temporary.unlink(missing_ok=True)


def compile_for(
    owner: Any,
    tag: Any,
    build: Callable[[], ca.Function],
    *,
    enabled: bool | None = None,
    flags: Sequence[str] = DEFAULT_FLAGS,
) -> CompiledFunction:
    """:func:`compile_function` of ``build()``, kept per ``owner`` object and ``tag``.

    For a Function built from ``owner`` alone (a plant step of the lifted ``f``, say): the
    first model of a structure builds and compiles (or loads) it, later models of the
    same structure get the kept result without building the Function, serializing it for
    its cache key or loading the library again.  The settings that decide the result
    (compiled or not, the cache folder, the compiler, the flags) are part of the key, so
    switching compilation off, pointing ``FLEXCTRL_CACHE`` elsewhere or changing ``$CC``
    builds anew.  A compilation that failed (the virtual machine's Function returned, with
    a warning) is not kept: the next model tries again, as it would without this.

    Parameters
    ----------
    owner : object
        What the Function is built from; the result is kept while it lives.
    tag : hashable
        Which of the owner's Functions (e.g. a step count).
    build : callable
        ``build()`` makes the Function, called only when nothing is kept.
    enabled : bool, optional
        ``False``: the virtual machine; ``None``: compile unless ``FLEXCTRL_NO_COMPILE`` is set.
    flags : sequence of str
        The C compiler's flags.

    Returns
    -------
    CompiledFunction
        As :func:`compile_function` returns it.
    """
    if enabled is None:
        enabled = not compile_disabled_by_env()
    settings = (
        "compiled",
        tag,
        bool(enabled),
        str(cache_directory()) if enabled else "",
        find_compiler() if enabled else "",
        tuple(flags),
    )
    kept = FROM_LIFTED.lookup(owner, settings)
    if kept is not None:
        return kept
    result = compile_function(build(), enabled=enabled, flags=flags)
    if result.compiled or not enabled:
        FROM_LIFTED.keep(owner, settings, result)
    return result


def _compile_or_load(
    fun: ca.Function, directory: Path, compiler: str, flags: tuple[str, ...]
) -> CompiledFunction | str:
    """The cached or freshly compiled library, or the reason it failed."""
    name = fun.name()
    library = directory / f"{name}_{cache_key(fun, flags, compiler)}.so"
    if library.is_file() and not trusted_file(library):
        log.warning(
            "cached library %s is not the user's alone (owner or write permission of others); "
            "rebuilding it instead of loading it",
            library,
        )
    elif library.is_file():
        try:
            return CompiledFunction(
                ca.external(name, str(library)),
                compiled=True,
                cache_hit=True,
                path=library,
                flags=flags,
            )
        except RuntimeError as exc:  # unreadable library: rebuild it
            log.warning("cached library %s could not be loaded (%s); recompiling", library, exc)
    start = time.perf_counter()
    try:
        _build(fun, library, compiler, flags)
        external = ca.external(name, str(library))
    except (OSError, RuntimeError, subprocess.SubprocessError) as exc:
        return f"flags {' '.join(flags)}: {str(exc).strip()[:300]}"
    seconds = time.perf_counter() - start
    log.info("compiled %s in %.2f s -> %s", name, seconds, library)
    return CompiledFunction(
        external, compiled=True, cache_hit=False, path=library, compile_seconds=seconds, flags=flags
    )


def _build(fun: ca.Function, library: Path, compiler: str, flags: tuple[str, ...]) -> None:
    library.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="build-", dir=library.parent) as tmp:
        source_name = f"{fun.name()}.c"
        generator = ca.CodeGenerator(source_name, {"with_header": False})
        generator.add(fun)
        generator.generate(tmp + os.sep)
        target = Path(tmp) / library.name
        result = subprocess.run(
            [
                compiler,
                *flags,
                "-shared",
                "-fPIC",
                "-o",
                str(target),
                str(Path(tmp) / source_name),
                "-lm",
            ],
            capture_output=True,
            text=True,
            timeout=COMPILE_TIMEOUT_S,
            check=False,
        )
        if result.returncode != 0:
            raise RuntimeError(result.stderr or result.stdout or f"exit status {result.returncode}")
        os.chmod(target, 0o700)
        os.replace(target, library)


#: The keys are :mod:`flexctrl.sim.library_keys`'s, re-exported for the callers that compile.
__all__ = [
    "DEFAULT_FLAGS",
    "ENV_NO_COMPILE",
    "PORTABLE_FLAGS",
    "QUICK_FLAGS",
    "CompiledFunction",
    "cache_key",
    "compile_by_recipe",
    "compile_disabled_by_env",
    "compile_for",
    "compile_function",
    "content_key",
    "find_compiler",
    "library_key",
]
