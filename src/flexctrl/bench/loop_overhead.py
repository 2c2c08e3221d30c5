"""The closed-loop benchmark: one whole closed-loop run against the plant's compiled simulation.

``run_wall_s`` is the wall time of
:func:`flexctrl.scenes.run_closed_loop_scene.run_closed_loop_scene` on
``studies/scenes/move_joint1_30deg.toml`` with the LQR (build, design, simulate, metrics,
verdict), warm: in-process, with the worker's :class:`~flexctrl.scenes.cache.SceneCache` after
a first run (models built, libraries compiled, the design and its reference table kept).
``plant_only_s`` is the plant's compiled RK4 simulation (:class:`flexctrl.sim.RK4`, its
energies, tip and deflections included) over the same duration at the same step with the
run's torques held: what the physics costs.  ``ratio = run_wall_s / plant_only_s``.

Both loops are measured in the same process, interleaved (``repeats`` rounds of python,
compiled and plant-only), so the machine's load moves them together: ``python`` runs one
Python iteration per sample (the loop of the optimising controllers), ``compiled`` the
one-call loop of the linear laws (:mod:`flexctrl.loop.compiled`).  ``cold_design`` repeats
the compiled run with a fresh design on the kept model (design, reference table and verdict
paid); ``fresh_configuration`` with everything fresh but the compiled libraries on disk (a
new configuration in a sweep: the model built, its constants lifted, Jacobians and reference
Functions built).  Medians of the rounds; the metrics of the two loops are compared
(``max_metric_relative_difference``).
"""

from __future__ import annotations

import dataclasses
import math
import os
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

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


def _rounds(scene, cache, results, integrator, x0, span, torques, repeats) -> dict:
    """Wall times (s) of each variant, ``repeats`` rounds interleaved."""
    from flexctrl.scenes.cache import SceneCache
    from flexctrl.scenes.run_closed_loop_scene import run_closed_loop_scene

    walls: dict[str, list[float]] = {
        "python": [],
        "compiled": [],
        "plant_only": [],
        "cold_design": [],
        "fresh_configuration": [],
    }
    for _ in range(repeats):
        for loop in ("python", "compiled"):
            start = time.perf_counter()
            results[loop] = run_closed_loop_scene(
                scene, cache=cache, on_divergence="record", loop=loop
            )
            walls[loop].append(time.perf_counter() - start)
        start = time.perf_counter()
        integrator.run(x0, span, u=torques)
        walls["plant_only"].append(time.perf_counter() - start)
        fresh = SceneCache()
        fresh._stores["models"] = cache._stores["models"]  # models built; design and verdict anew
        start = time.perf_counter()
        run_closed_loop_scene(scene, cache=fresh, on_divergence="record", loop="compiled")
        walls["cold_design"].append(time.perf_counter() - start)
        start = time.perf_counter()
        run_closed_loop_scene(scene, cache=SceneCache(), on_divergence="record", loop="compiled")
        walls["fresh_configuration"].append(time.perf_counter() - start)
    return walls


def bench_loop(
    scene_path: str | Path = DEFAULT_SCENE,
    controller: str | Path = DEFAULT_CONTROLLER,
    *,
    repeats: int = 5,
) -> dict[str, Any]:
    """Measure what the module docstring describes; returns a JSON-serialisable dict."""
    from flexctrl.scenes.cache import SceneCache
    from flexctrl.scenes.run_closed_loop_scene import run_closed_loop_scene
    from flexctrl.sim import RK4
    from flexctrl.spec.scene import load_scene

    scene = dataclasses.replace(load_scene(scene_path), controller=str(controller))
    cache = SceneCache()
    first = time.perf_counter()
    results = {
        loop: run_closed_loop_scene(scene, cache=cache, on_divergence="record", loop=loop)
        for loop in ("python", "compiled")
    }
    first = time.perf_counter() - first
    plant, trajectory = results["compiled"].model, results["compiled"].trajectory
    dt, duration = float(trajectory.meta["dt"]), float(scene.plant.duration)
    integrator = RK4(plant, dt, compile=scene.plant.solver.get("compile")).setup()
    torques = trajectory.inputs[
        :-1
    ]  # the loop runs whole samples: 942 x 17 steps = 8.007 s for the LQR
    x0, span = trajectory.states[0], torques.shape[0] * dt
    walls = _rounds(scene, cache, results, integrator, x0, span, torques, repeats)
    med = {k: statistics.median(v) for k, v in walls.items()}
    run_wall, plant_only = med["compiled"], med["plant_only"]
    return {
        "scene": str(scene_path),
        "controller": str(controller),
        "fidelity": str(scene.plant.fidelity),
        "dt": dt,
        "duration_s": duration,
        "simulated_s": span,
        "sample_time": results["compiled"].controller.sample_time,
        "repeats": repeats,
        "run_wall_s": run_wall,
        "plant_only_s": plant_only,
        "ratio": run_wall / plant_only,
        "python": {"run_wall_s": med["python"], "ratio": med["python"] / plant_only},
        "cold_design": {
            "run_wall_s": med["cold_design"],
            "ratio": med["cold_design"] / plant_only,
            "note": "models built, but design, reference table and linear verdict computed afresh",
        },
        "fresh_configuration": {
            "run_wall_s": med["fresh_configuration"],
            "ratio": med["fresh_configuration"] / plant_only,
            "note": "a fresh cache: model built and everything derived from it anew; compiled "
            "libraries from disk",
        },
        "speedup_vs_python": med["python"] / run_wall,
        "max_metric_relative_difference": metric_difference(
            results["python"].metrics, results["compiled"].metrics
        ),
        "metric_differences": metric_differences(
            results["python"].metrics, results["compiled"].metrics
        ),
        "wall_times_s": walls,
        "first_runs_s": first,
        "target_ratio": TARGET_RATIO,
        "met": bool(run_wall / plant_only <= TARGET_RATIO),
        "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "stable": bool(results["compiled"].metrics["stable"]),
        "tip_residual_rms_m": results["compiled"].metrics["tip_residual_rms"],
        "omega_max_dt": float(plant.omega_max) * dt if math.isfinite(plant.omega_max) else None,
    }


def format_loop(result: dict[str, Any]) -> str:
    """Human-readable lines of :func:`bench_loop`'s result."""
    return "\n".join(
        [
            f"flexctrl bench loop: {Path(result['scene']).name} with "
            f"{Path(result['controller']).name} "
            f"({result['fidelity']}, dt {result['dt']:g} s, {result['duration_s']:g} s), medians "
            f"of {result['repeats']} rounds",
            f"  plant only (compiled RK4)   {result['plant_only_s'] * 1e3:8.1f} ms",
            f"  run, compiled loop          {result['run_wall_s'] * 1e3:8.1f} ms   ratio "
            f"{result['ratio']:.2f} "
            f"(target <= {result['target_ratio']:g}: {'met' if result['met'] else 'NOT met'})",
            f"  run, python loop            {result['python']['run_wall_s'] * 1e3:8.1f} ms   "
            f"ratio {result['python']['ratio']:.2f}",
            f"  run, compiled, fresh design {result['cold_design']['run_wall_s'] * 1e3:8.1f} ms  "
            " ratio "
            f"{result['cold_design']['ratio']:.2f}",
            "  run, compiled, fresh config "
            f"{result['fresh_configuration']['run_wall_s'] * 1e3:8.1f} ms   ratio "
            f"{result['fresh_configuration']['ratio']:.2f}",
            "  compiled / python metrics: largest relative difference "
            f"{result['max_metric_relative_difference']:.2g}",
        ]
    )
