"""Running described scenes of every kind: open-loop arm, closed-loop and finite-element scenes.

:func:`run_scene` dispatches on the scene's ``kind`` through :data:`SCENE_RUNNERS`, the
one place runners are named (the descriptions' readers are
:data:`flexctrl.spec.scene.SCENE_READERS`).  Modules:

``arm``, ``arm_scene``          an open-loop arm scene (building blocks; the runner)
``loop_setup``, ``closed_loop`` a closed-loop scene (models and controller; the runner)
``fem``                         the finite-element scenes
``auto``                        running scenes for the automatic-fidelity ladder
``cache``                       :class:`~flexctrl.scenes.cache.SceneCache`, owned by the caller
``models``                      a model file built (:func:`flexctrl.load_model`)
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

#: Scene kind -> ``"module:runner"``; a runner takes ``(scene, out, **options)``.
SCENE_RUNNERS: dict[str, str] = {
    "arm": "flexctrl.scenes.run_arm_scene:run_arm_scene",
    "closed_loop": "flexctrl.scenes.run_closed_loop_scene:run_closed_loop_scene",
    "sliding_beam": "flexctrl.scenes.run_fem_scene:run_scene",
    "rp_arm": "flexctrl.scenes.run_fem_scene:run_scene",
    "telescoping": "flexctrl.scenes.run_fem_scene:run_scene",
}


def run_scene(scene, out: str | Path | None = None, **options: Any):
    """Run ``scene`` (any kind of :data:`SCENE_RUNNERS`), writing results to ``out`` when given.

    Parameters
    ----------
    scene
        From :func:`flexctrl.load_scene`.
    out : str or Path, optional
        Folder for ``trajectory.csv``, ``summary.json`` and the figures; nothing is written when
        None.
    **options
        The kind's runner's keywords: ``controller`` (a file or a controller designed in
        Python), ``fidelity``, ``plots``, ``cache`` (:class:`~flexctrl.scenes.cache.SceneCache`) ...

    Returns
    -------
    SceneResult or ClosedLoopResult or FemSceneResult

    ``fidelity = "auto"`` is resolved by the kind's runner: for ``kind = "arm"`` by
    :func:`flexctrl.scenes.run_arm_scene.run_arm_scene`, for ``kind = "closed_loop"`` (the
    plant's fidelity) by :func:`flexctrl.scenes.run_closed_loop_scene.run_closed_loop_scene`.
    """
    module, _, name = SCENE_RUNNERS[scene.kind].partition(":")
    return getattr(importlib.import_module(module), name)(scene, out, **options)
