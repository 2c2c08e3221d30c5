"""Where flexctrl keeps what it computes once and reuses: compiled libraries, lookup tables.

The cache is the user's cache folder (``platformdirs.user_cache_dir("flexctrl")``:
``$XDG_CACHE_HOME/flexctrl``, by default ``~/.cache/flexctrl`` on Linux), shared by every
working folder and every clone; ``$FLEXCTRL_CACHE`` names another.  Entries are keyed by
their content, so sharing them is safe.
"""

import os
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
        The folder (not created here; :func:`flexctrl.sim.compile.private_directory` creates
        it owner-only).
    """
    if explicit is not None:
        return Path(explicit)
    env = os.environ.get(ENV_CACHE, "").strip()
    if env:
        return Path(env)
    from platformdirs import user_cache_dir

    return Path(user_cache_dir("flexctrl", appauthor=False))


__all__ = ["ENV_CACHE", "cache_directory"]
