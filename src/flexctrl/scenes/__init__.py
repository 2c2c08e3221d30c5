"""Running described scenes of every kind: open-loop arm, closed-loop and finite-element scenes.

:func:`run_scene` dispatches on the scene's ``kind`` through
:data:`flexctrl.scenes.scene_runners.SCENE_RUNNERS`, the one place runners are named (the
descriptions' readers are :data:`flexctrl.spec.scene.SCENE_READERS`).  Modules:

``arm_setup``, ``run_arm_scene``
    an open-loop arm scene (building blocks; the runner);
``loop_setup``, ``run_closed_loop_scene``
    a closed-loop scene (models and controller; the runner);
``run_fem_scene``
    the finite-element scenes;
``auto``, ``auto_closed_loop``
    running scenes for the automatic-fidelity ladder;
``auto_linear``
    a closed loop's rungs estimated on linearised plants;
``cache``
    :class:`~flexctrl.scenes.cache.SceneCache`, owned by the caller;
``model_files``
    a model file built (:func:`flexctrl.load_model`);
``scene_runners``
    the runner of each scene kind.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any


def run_scene(scene, out: str | Path | None = None, **options: Any):
    """Run ``scene`` (any kind of :data:`~flexctrl.scenes.scene_runners.SCENE_RUNNERS`).

    ``fidelity = "auto"`` is resolved by the kind's runner: for ``kind = "arm"`` by
    :func:`flexctrl.scenes.run_arm_scene.run_arm_scene`, for ``kind = "closed_loop"`` (the
    plant's fidelity) by :func:`flexctrl.scenes.run_closed_loop_scene.run_closed_loop_scene`.

    Parameters
    ----------
    scene : ArmScene or ClosedLoopScene or FemScene
        From :func:`flexctrl.load_scene`.
    out : str or Path, optional
        Folder for ``trajectory.csv``, ``summary.json`` and the figures; nothing is written
        when None.
    **options
        The kind's runner's keywords: ``controller`` (a file or a controller designed in
        Python), ``fidelity``, ``plots``, ``cache`` (:class:`~flexctrl.scenes.cache.SceneCache`)
        ...

    Returns
    -------
    SceneResult or ClosedLoopResult or FemSceneResult
        What the kind's runner returns.
    """
    # the runners are imported here, not at the package's top: importing flexctrl.scenes for its
    # SceneCache loads no model, integrator or controller code
    from flexctrl.scenes.scene_runners import SCENE_RUNNERS

    return SCENE_RUNNERS[scene.kind](scene, out, **options)
