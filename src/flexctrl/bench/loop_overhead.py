"""The closed-loop benchmark: a whole closed-loop scene run against the plant's simulation alone.

``run_wall_s`` is the wall time of
:func:`flexctrl.scenes.run_closed_loop_scene.run_closed_loop_scene` on
``studies/scenes/move_joint1_30deg.toml`` with the LQR (build, design, simulate, metrics,
verdict), warm: in-process, with the worker's :class:`~flexctrl.scenes.cache.SceneCache`
after a first run (models built, libraries compiled, the design and its reference table
kept).  ``plant_only_s`` is the plant's compiled RK4 simulation (:class:`flexctrl.sim.RK4`,
its energies, tip and deflections included) over the same duration at the same step with
the run's torques held: what the physics costs.  ``ratio = run_wall_s / plant_only_s``.

``cold_design`` repeats the run with a fresh design on the kept model (design, reference
table and verdict paid); ``fresh_configuration`` with everything fresh but the compiled
libraries on disk (a new configuration in a sweep: the model built, its constants lifted,
Jacobians and reference Functions built).  The runs are interleaved (``repeats`` rounds of
warm, plant-only, cold design and fresh configuration), so the machine's load moves them
together; the figures are medians of the rounds.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.scenes.cache import SceneCache
from flexctrl.scenes.run_closed_loop_scene import run_closed_loop_scene
from flexctrl.sim import RK4
from flexctrl.spec.scene import load_scene
from flexctrl.spec.shipped import data_root

REPO = data_root()
DEFAULT_SCENE = REPO / "studies" / "scenes" / "move_joint1_30deg.toml"
DEFAULT_CONTROLLER = REPO / "controllers" / "lqr.toml"
TARGET_RATIO = 2.0
#: Metrics that are wall times or their ratios (they differ between any two runs).
TIMING_METRICS = (
    "controller_time_median",
    "controller_time_p95",
    "controller_time_max",
    "choice_time_s",
    "choice_cost_ratio",
)


#: Magnitude (SI) below which a metric is round-off, compared absolutely: ``final_tip_error`` of a
#: settled LQR run is 6e-12 m, a distance between two tip positions of about 2 m.
FLOOR = 1e-9


def metric_differences(a: dict, b: dict) -> dict[str, float]:
    """Per non-timing metric: the relative difference between two runs (0 when equal).

    Relative to the larger magnitude of the two; for metrics below :data:`FLOOR` in
    both runs, the absolute difference (they are round-off).
    """
    out = {}
    for key, value in a.items():
        if key in TIMING_METRICS:
            continue
        x, y = np.ravel(np.asarray(value, dtype=float)), np.ravel(np.asarray(b[key], dtype=float))
        same = (x == y) | (np.isnan(x) & np.isnan(y))
        scale = np.maximum(np.abs(x), np.abs(y))
        diff = np.where(same, 0.0, np.abs(x - y) / np.where(scale > FLOOR, scale, 1.0))
        out[key] = float(np.max(diff, initial=0.0))
    return out


def metric_difference(a: dict, b: dict) -> float:
    """The largest of :func:`metric_differences`."""
    return max(metric_differences(a, b).values(), default=0.0)


def bench_loop(
    scene_path: str | Path = DEFAULT_SCENE,
    controller: str | Path = DEFAULT_CONTROLLER,
    *,
    repeats: int = 5,
) -> dict[str, Any]:
    """Measure what the module docstring describes.

    Parameters
    ----------
    scene_path : str or Path
        A closed-loop scene file.
    controller : str or Path
        A controller file.
    repeats : int
        Rounds; the figures are their medians.

    Returns
    -------
    dict
        JSON-ready: ``run_wall_s``, ``plant_only_s`` (s), ``ratio``, ``cold_design``,
        ``fresh_configuration``, ``wall_times_s`` and the run's facts.
    """
    scene = dataclasses.replace(load_scene(scene_path), controller=str(controller))
    cache = SceneCache()
    first = time.perf_counter()
    result = run_closed_loop_scene(scene, cache=cache, on_divergence="record")
    first = time.perf_counter() - first
    plant_only = _plant_only(scene, result)
    walls: dict[str, list[float]] = {
        "compiled": [],
        "plant_only": [],
        "cold_design": [],
        "fresh_configuration": [],
    }
    for _ in range(repeats):
        result = _timed(walls["compiled"], lambda: _run(scene, cache))
        _timed(walls["plant_only"], plant_only)
        fresh = SceneCache()
        fresh._stores["models"] = cache._stores["models"]  # models built; the rest anew
        _timed(walls["cold_design"], functools.partial(_run, scene, fresh))
        _timed(walls["fresh_configuration"], lambda: _run(scene, SceneCache()))
    med = {k: statistics.median(v) for k, v in walls.items()}
    return _figures(scene_path, controller, scene, result, med, walls, first, repeats)


def _run(scene, cache: SceneCache):
    return run_closed_loop_scene(scene, cache=cache, on_divergence="record")


def _timed(walls: list[float], call):
    """``call()``, its wall time (s) appended to ``walls``."""
    start = time.perf_counter()
    value = call()
    walls.append(time.perf_counter() - start)
    return value


def _plant_only(scene, result):
    """The plant's compiled RK4 run over the loop's samples with the loop's torques held."""
    trajectory = result.trajectory
    dt = float(trajectory.meta["dt"])
    integrator = RK4(result.model, dt, compile=scene.plant.solver.get("compile")).setup()
    torques = trajectory.inputs[:-1]  # the loop runs whole samples
    x0, span = trajectory.states[0], torques.shape[0] * dt
    return lambda: integrator.run(x0, span, u=torques)


def _figures(scene_path, controller, scene, result, med, walls, first, repeats) -> dict[str, Any]:
    """The benchmark's JSON: medians, their ratios to the plant alone, the run's facts."""
    plant, trajectory = result.model, result.trajectory
    dt = float(trajectory.meta["dt"])
    run_wall, plant_only = med["compiled"], med["plant_only"]
    return {
        "scene": str(scene_path),
        "controller": str(controller),
        "fidelity": str(scene.plant.fidelity),
        "dt": dt,
        "duration_s": float(scene.plant.duration),
        "simulated_s": (trajectory.inputs.shape[0] - 1) * dt,
        "sample_time": result.controller.sample_time,
        "repeats": repeats,
        "run_wall_s": run_wall,
        "plant_only_s": plant_only,
        "ratio": run_wall / plant_only,
        "cold_design": {
            "run_wall_s": med["cold_design"],
            "ratio": med["cold_design"] / plant_only,
            "note": "models built, but design, reference table and linear verdict computed afresh",
        },
        "fresh_configuration": {
            "run_wall_s": med["fresh_configuration"],
            "ratio": med["fresh_configuration"] / plant_only,
            "note": "a fresh cache: model built and everything derived from it anew; "
            "compiled libraries from disk",
        },
        "wall_times_s": walls,
        "first_runs_s": first,
        "target_ratio": TARGET_RATIO,
        "met": bool(run_wall / plant_only <= TARGET_RATIO),
        "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "stable": bool(result.metrics["stable"]),
        "tip_residual_rms_m": result.metrics["tip_residual_rms"],
        "omega_max_dt": float(plant.omega_max) * dt if math.isfinite(plant.omega_max) else None,
    }


def format_loop(result: dict[str, Any]) -> str:
    """Human-readable lines of :func:`bench_loop`'s result."""
    cold, fresh = result["cold_design"], result["fresh_configuration"]
    verdict = "met" if result["met"] else "NOT met"
    return "\n".join(
        [
            f"flexctrl bench loop: {Path(result['scene']).name} with "
            f"{Path(result['controller']).name} ({result['fidelity']}, dt {result['dt']:g} s, "
            f"{result['duration_s']:g} s), medians of {result['repeats']} rounds",
            f"  plant only (compiled RK4)   {result['plant_only_s'] * 1e3:8.1f} ms",
            f"  run, warm                   {result['run_wall_s'] * 1e3:8.1f} ms   ratio "
            f"{result['ratio']:.2f} (target <= {result['target_ratio']:g}: {verdict})",
            f"  run, fresh design           {cold['run_wall_s'] * 1e3:8.1f} ms   ratio "
            f"{cold['ratio']:.2f}",
            f"  run, fresh configuration    {fresh['run_wall_s'] * 1e3:8.1f} ms   ratio "
            f"{fresh['ratio']:.2f}",
        ]
    )
