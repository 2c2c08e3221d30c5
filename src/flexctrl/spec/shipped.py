"""The description files that ship with flexctrl, found by name from any folder.

The package carries its models, controllers, scenes, studies, tunings and notebooks as
package data (``flexctrl/data/``, found with :mod:`importlib.resources`), so a name works
wherever a path does::

    fc.load_model("subedi3link")                 # data/models/subedi3link.toml
    fc.load_controller("lqr")                    # data/controllers/lqr.toml
    flexctrl study quickstart --out DIR          # data/studies/quickstart.toml

A path that exists is always used as given.  A relative path that does not exist is also
looked up inside the shipped tree (``models/subedi3link.toml``,
``studies/scenes/move_joint1_30deg.toml``), so the paths written in the shipped files and
in commands typed in a clone of the repository work from any folder.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from flexctrl.errors import SpecError

#: File kind -> the folders of the shipped tree that hold it, searched in this order.
FOLDERS: dict[str, tuple[str, ...]] = {
    "model": ("models",),
    "controller": ("controllers",),
    "scene": ("studies/scenes",),
    "study": ("studies",),
    "tuning": ("studies", "studies/tuning"),
    "notebook": ("studies/notebooks",),
}
_SUFFIX = {"notebook": ".ipynb"}


def data_root() -> Path:
    """The folder of the shipped description files (``flexctrl/data``)."""
    return Path(str(resources.files("flexctrl") / "data"))


def names(kind: str | None = None) -> list[str]:
    """The names of the shipped files of ``kind`` (``"model"``, ``"controller"``, ...), sorted.

    None: of every kind.
    """
    if kind is None:
        return sorted({name for k in FOLDERS for name in names(k)})
    suffix = _SUFFIX.get(kind, ".toml")
    found: set[str] = set()
    for folder in FOLDERS[kind]:
        found.update(p.stem for p in (data_root() / folder).glob(f"*{suffix}"))
    return sorted(found)


def _by_name(name: str, kind: str | None) -> Path | None:
    if kind is None:
        return next((p for k in FOLDERS if (p := _by_name(name, k)) is not None), None)
    suffix = _SUFFIX.get(kind, ".toml")
    stem = name[: -len(suffix)] if name.endswith(suffix) else name
    for folder in FOLDERS[kind]:
        candidate = data_root() / folder / f"{stem}{suffix}"
        if candidate.is_file():
            return candidate
    return None


def find(path: str | Path, kind: str | None, base_dir: Path | None = None) -> Path:
    """The file that ``path`` names: itself if it exists, else a shipped file.

    Parameters
    ----------
    path : str or Path
        A file path (absolute, or relative to ``base_dir`` and then the working folder),
        a path inside the shipped tree (``models/subedi3link.toml``), or a shipped name
        (``subedi3link``).
    kind : str or None
        One of the keys of :data:`FOLDERS`: the folders a bare name is looked up in (None:
        every folder).
    base_dir : Path, optional
        Folder of the file that refers to ``path`` (relative paths are tried there first).

    Returns
    -------
    Path
        An existing file.

    Raises
    ------
    SpecError
        Naming what was looked at and the shipped names of ``kind``.
    """
    if kind is not None and kind not in FOLDERS:
        raise ValueError(f"unknown file kind {kind!r}; allowed: {', '.join(FOLDERS)}")
    given = Path(path)
    candidates = (
        [given] if given.is_absolute() else [(base_dir or Path.cwd()) / given, Path.cwd() / given]
    )
    if not given.is_absolute():
        candidates.append(data_root() / given)
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    if not given.is_absolute() and len(given.parts) == 1:
        shipped = _by_name(str(given), kind)
        if shipped is not None:
            return shipped
    looked = ", ".join(dict.fromkeys(f"'{c}'" for c in candidates))
    raise SpecError(
        f"file not found (looked at {looked}); allowed: an existing file or a shipped "
        f"{kind or 'file'} name: {', '.join(names(kind))}",
        source=str(path),
    )


__all__ = ["FOLDERS", "data_root", "find", "names"]
