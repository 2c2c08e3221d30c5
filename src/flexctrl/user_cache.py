"""Where flexctrl keeps what it computes once and reuses: compiled libraries, lookup tables.

The cache is the user's cache folder (``platformdirs.user_cache_dir("flexctrl")``:
``$XDG_CACHE_HOME/flexctrl``, by default ``~/.cache/flexctrl`` on Linux), shared by every
working folder and every clone; ``$FLEXCTRL_CACHE`` names another.  Entries are keyed by
their content, so sharing them is safe.
"""

import functools
import os
import stat
import tempfile
import warnings
from pathlib import Path

#: The environment variable that names another cache folder.
ENV_CACHE = "FLEXCTRL_CACHE"


def cache_directory(explicit: str | os.PathLike | None = None) -> Path:
    """The cache folder: ``explicit``, else ``$FLEXCTRL_CACHE``, else the user's cache folder.

    Parameters
    ----------
    explicit : path, optional
        A folder chosen by the caller.

    Returns
    -------
    Path
        The folder (not created here; :func:`private_directory` creates
        it owner-only).
    """
    if explicit is not None:
        return Path(explicit)
    env = os.environ.get(ENV_CACHE, "").strip()
    if env:
        return Path(env)
    from platformdirs import user_cache_dir

    return Path(user_cache_dir("flexctrl", appauthor=False))


def trusted_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is the user's alone: the effective user's, not writable by group or others.

    A symbolic link is never trusted (its target could change); a folder must be one.

    Parameters
    ----------
    path : path
        A file or folder.

    Returns
    -------
    bool
        ``False`` too when ``path`` does not exist.
    """
    try:
        info = os.lstat(path)
    except OSError:
        return False
    if stat.S_ISLNK(info.st_mode) or not (stat.S_ISREG(info.st_mode) or stat.S_ISDIR(info.st_mode)):
        return False
    return info.st_uid == os.geteuid() and not info.st_mode & (stat.S_IWGRP | stat.S_IWOTH)


def private_directory(directory: Path) -> Path:
    """``directory`` (created owner-only if missing) if it is the user's alone, else a private one.

    The temporary folder (mode 0700, one per process and untrusted folder) keeps this
    process's libraries out of reach of the folder's other writers; a warning names the
    folder and why it was not used.

    Parameters
    ----------
    directory : pathlib.Path
        The cache folder asked for.

    Returns
    -------
    pathlib.Path
        The folder to use.
    """
    if not directory.exists():
        directory.mkdir(parents=True, exist_ok=True, mode=0o700)
        if os.stat(directory).st_uid == os.geteuid():
            os.chmod(directory, 0o700)
    if trusted_file(directory):
        return directory
    return _fallback_directory(str(directory))


@functools.cache
def _fallback_directory(untrusted: str) -> Path:
    try:
        info = os.lstat(untrusted)
        why = (
            f"owned by uid {info.st_uid}, mode {stat.S_IMODE(info.st_mode):o}"
            if not stat.S_ISLNK(info.st_mode)
            else "a symbolic link"
        )
    except OSError as exc:
        why = str(exc)
    fallback = Path(tempfile.mkdtemp(prefix="flexctrl-cache-"))
    warnings.warn(
        f"the compiled-library cache '{untrusted}' is not the user's alone ({why}); libraries "
        f"that others could write are never loaded: compiling into the private folder "
        f"'{fallback}' for this process instead (set ${ENV_CACHE} to a folder only you can write)",
        stacklevel=3,
    )
    return fallback


__all__ = ["ENV_CACHE", "cache_directory", "private_directory", "trusted_file"]
