"""Running described scenes of every kind: open-loop arm, closed-loop and finite-element scenes.

:func:`run_scene` dispatches on the scene's ``kind`` through :func:`scene_runners`, the
one place runners are named (the descriptions' readers are
:data:`flexctrl.spec.scene.SCENE_READERS`).  Modules:

``arm_setup``, ``run_arm_scene``               an open-loop arm scene (its pieces; the runner)
``loop_setup``, ``run_closed_loop_scene``      a closed-loop scene (models and controller; the
                                               runner)
``run_fem_scene``                              the finite-element scenes
``auto``, ``auto_linear``                      running scenes for the automatic-fidelity ladder
``cache``                                      :class:`~flexctrl.scenes.cache.SceneCache`, owned by
                                               the caller
``model_files``                                a model file built (:func:`flexctrl.load_model`)
"""

from __future__ import annotations

from pathlib import Path
from typing import Any


def scene_runners() -> dict:
    """Scene kind -> runner; a runner takes ``(scene, out, **options)``.

    Imported when a scene runs, so that importing this package (for its
    :class:`~flexctrl.scenes.cache.SceneCache`, say) loads no runner.
    """
    from flexctrl.scenes.run_arm_scene import run_arm_scene
    from flexctrl.scenes.run_closed_loop_scene import run_closed_loop_scene
    from flexctrl.scenes.run_fem_scene import run_scene as run_fem_scene

    return {
        "arm": run_arm_scene,
        "closed_loop": run_closed_loop_scene,
        "sliding_beam": run_fem_scene,
        "rp_arm": run_fem_scene,
        "telescoping": run_fem_scene,
    }


def run_scene(scene, out: str | Path | None = None, **options: Any):
    """Run ``scene`` (any kind of :func:`scene_runners`), writing results to ``out`` when given.

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
    return scene_runners()[scene.kind](scene, out, **options)
