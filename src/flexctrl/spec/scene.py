"""Scene files (``studies/scenes/*.toml``) of every kind, read and validated in one place.

The top-level ``kind`` (default ``"arm"``) selects the reader from :data:`SCENE_READERS`,
the one place where scene kinds are known to the descriptions:

``arm``
    :func:`flexctrl.spec.arm_scene.read_arm_scene` ->
    :class:`~flexctrl.spec.arm_scene.ArmScene`
``closed_loop``
    :func:`flexctrl.spec.closed_loop_scene.read_closed_loop_scene` ->
    :class:`~flexctrl.spec.closed_loop_scene.ClosedLoopScene`
``sliding_beam``, ``rp_arm``, ``telescoping``
    :func:`flexctrl.spec.fem_scene.read_fem_scene` -> :class:`~flexctrl.spec.fem_scene.FemScene`

Running a scene is a higher layer's job (:func:`flexctrl.scenes.run_scene`).
:func:`load_scene` applies ``--set KEY=VALUE`` overrides to the parsed document before
validation, so an override is checked exactly like the file.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from flexctrl.errors import keyword_checked
from flexctrl.spec import shipped
from flexctrl.spec.arm_scene import ArmScene, InputSpec, read_arm_scene
from flexctrl.spec.closed_loop_scene import read_closed_loop_scene
from flexctrl.spec.fem_scene import read_fem_scene
from flexctrl.spec.overrides import apply_overrides
from flexctrl.spec.reader import TableReader, read_toml

__all__ = ["SCENE_READERS", "ArmScene", "InputSpec", "load_scene", "scene_from_document"]

#: Scene kinds: kind -> reader; a reader takes ``(document, source, base_dir)`` and returns a scene.
SCENE_READERS: dict[str, Callable[..., Any]] = {
    "arm": read_arm_scene,
    "closed_loop": read_closed_loop_scene,
    "sliding_beam": read_fem_scene,
    "rp_arm": read_fem_scene,
    "telescoping": read_fem_scene,
}


@keyword_checked
def load_scene(path: str | Path, overrides: Iterable[str] = ()):
    """Load, override and validate a scene file; the scene type depends on its ``kind``.

    Parameters
    ----------
    path : str or Path
        A scene file (``studies/scenes/*.toml``).
    overrides : iterable of str
        ``KEY=VALUE`` strings (``duration=3.0``, ``target.move=[45, 0, 0]``: degrees as in
        the file), applied before validation.

    Returns
    -------
    ArmScene, ClosedLoopScene or FemScene
        Plain frozen data, angles in radians; run it with :func:`flexctrl.run_scene`.

    Raises
    ------
    SpecError
        Naming the file, the key, the value and what is allowed.
    """
    path = shipped.find(path, "scene")
    document = apply_overrides(read_toml(path), overrides, source=f"{path} (--set)")
    return scene_from_document(document, str(path), path.resolve().parent)


def scene_from_document(document: dict[str, Any], source: str, base_dir: Path | None = None):
    """Validate a parsed scene document (dispatching on ``kind``)."""
    kind = document.get("kind", "arm")
    if kind not in SCENE_READERS:
        TableReader(document, source).string("kind", choices=tuple(SCENE_READERS))
    return SCENE_READERS[kind](document, source, base_dir or Path.cwd())
