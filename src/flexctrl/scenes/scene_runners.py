"""The scene kinds' runners: kind -> the function that runs a scene of it.

Each runner takes ``(scene, out, **options)``.  The descriptions' readers are
:data:`flexctrl.spec.scene.SCENE_READERS`; :func:`flexctrl.scenes.run_scene` dispatches here.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from flexctrl.scenes.run_arm_scene import run_arm_scene
from flexctrl.scenes.run_closed_loop_scene import run_closed_loop_scene
from flexctrl.scenes.run_fem_scene import run_scene as run_fem_scene

#: Scene kind -> runner.
SCENE_RUNNERS: dict[str, Callable[..., Any]] = {
    "arm": run_arm_scene,
    "closed_loop": run_closed_loop_scene,
    "sliding_beam": run_fem_scene,
    "rp_arm": run_fem_scene,
    "telescoping": run_fem_scene,
}
