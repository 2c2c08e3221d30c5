"""Running an open-loop arm scene (``kind = "arm"``): model, simulation, files.

Examples
--------
>>> from flexctrl.spec.scene import load_scene
>>> from flexctrl.scenes import run_scene
>>> scene = load_scene("studies/scenes/bangbang.toml", ["duration=0.05", "fidelity='amm:1'"])
>>> result = run_scene(scene)
>>> float(result.trajectory.time[-1]), result.trajectory.states.shape
(0.05, (51, 12))
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from flexctrl.fidelity.ladder import check_tolerance
from flexctrl.scenes.arm_setup import SceneResult, model_facts, simulate_arm_scene
from flexctrl.scenes.auto import choose_fidelity, prepared
from flexctrl.scenes.cache import SceneCache
from flexctrl.sim.trajectory import jsonable
from flexctrl.spec.arm_scene import ArmScene
from flexctrl.spec.fidelity import parse_fidelity


def resolve_auto(
    scene: ArmScene, cache: SceneCache | None = None, **options: Any
) -> tuple[ArmScene, Any]:
    """For ``fidelity = "auto"``: the scene at the chosen fidelity, integrator and step; the choice.

    Runs :func:`flexctrl.scenes.auto.choose_fidelity` with the scene's
    ``tolerance`` and ``options`` (keywords of ``choose_fidelity``, e.g. ``top``;
    kept in ``cache``).  The returned scene keeps the scene's
    solver options only when the chosen integrator is the scene's.  Scenes with a
    concrete fidelity are returned unchanged with None.
    """
    if scene.fidelity.kind != "auto":
        return scene, None
    tol = check_tolerance(scene.tolerance, source=scene.source, key="tolerance")
    options.setdefault("checks", scene.fidelity_checks)
    choice = choose_fidelity(scene, tol, cache=cache, **options)
    solver = dict(scene.solver) if choice.integrator == scene.integrator else {}
    chosen = dataclasses.replace(
        scene, fidelity=choice.choice, integrator=choice.integrator, dt=choice.dt, solver=solver
    )
    return chosen, choice


def run_arm_scene(
    scene: ArmScene,
    out: str | Path | None = None,
    *,
    plots: bool | None = None,
    fidelity=None,
    auto_options: dict[str, Any] | None = None,
    cache: SceneCache | None = None,
    **integrator_options: Any,
) -> SceneResult:
    """Build, simulate and (with ``out``) write a ``kind = "arm"`` scene.

    With ``fidelity = "auto"`` (scene or override) the model, integrator and step
    are chosen by :func:`flexctrl.scenes.auto.choose_fidelity` from the
    scene's ``tolerance``; the choice and its evidence are recorded in the summary
    under ``"fidelity_choice"``.  The run then uses the chosen step, which may be a
    whole fraction of the scene's ``dt`` (RK4 stability), so the trajectory can hold
    more samples than the scene's grid.

    Parameters
    ----------
    scene
        From :func:`flexctrl.spec.scene.load_scene`.
    out
        Folder for ``trajectory.csv``, ``summary.json`` and PNGs; nothing is written when None.
    plots
        Override the scene's ``outputs.plots``.
    fidelity
        Override the scene's fidelity.
    auto_options
        Keywords of :func:`~flexctrl.scenes.auto.choose_fidelity` (``top``,
        ``reference``, ``safety``, ...) for ``fidelity = "auto"``.
    **integrator_options
        Passed to the integrator (e.g. ``compile=False``, ``cache_dir``).
    """
    if fidelity is not None:
        scene = dataclasses.replace(scene, fidelity=parse_fidelity(fidelity, source="--fidelity"))
    requested = scene
    cache = SceneCache() if cache is None else cache
    scene, choice = resolve_auto(scene, cache, **(auto_options or {}))
    if choice is not None and not integrator_options:
        model, integrator = prepared(scene, cache)  # built while choosing: reuse them
        trajectory, model, _arm = simulate_arm_scene(scene, model=model, integrator=integrator)
    else:
        trajectory, model, _arm = simulate_arm_scene(scene, **integrator_options)
    extra: dict[str, Any] = {"scene": requested.settings(), "model_info": model_facts(model)}
    if choice is not None:
        extra["fidelity_choice"] = choice.to_dict()
    summary = trajectory.summary(scene.fft_peaks, scene.fft_span)
    summary.update(jsonable(extra))
    files: list[Path] = []
    if out is not None:
        paths = trajectory.save(out, extra, fft_count=scene.fft_peaks, fft_span=scene.fft_span)
        files += list(paths.values())
        if scene.plots if plots is None else plots:
            files += trajectory.plot(out)
    return SceneResult(
        scene=scene, trajectory=trajectory, summary=summary, files=files, model=model
    )
