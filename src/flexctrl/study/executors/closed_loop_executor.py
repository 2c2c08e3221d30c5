"""The ``closed_loop`` executor: one closed-loop scene run from a study's settings.

The run's model, payload, configuration, fidelity and seed become scene overrides
(:func:`flexctrl.study.outputs.scene_overrides`); the scene runs with
``on_divergence = "record"`` so an unstable loop is a row with ``stable = 0``, not a
failed run.  Models and fidelity choices are kept in the worker's
:func:`~flexctrl.study.outputs.worker_scene_cache`.
"""

from __future__ import annotations

import json
import math
import time

from flexctrl.errors import FlexctrlError, SpecError
from flexctrl.scenes.run_closed_loop_scene import check_auto, resolve_auto, run_closed_loop_scene
from flexctrl.spec.controller_reader import load_controller
from flexctrl.spec.scene import load_scene
from flexctrl.study.outputs import RunOutput, overrides_for, scene_overrides, worker_scene_cache
from flexctrl.study.shared_choice import choice_settings


def _scene_overrides(settings: dict) -> list[str]:
    seed = () if settings.get("seed") is None else (f"noise.seed={int(settings['seed'])}",)
    return scene_overrides(settings, seed)


def check_settings(settings: dict) -> None:
    """Validate one study run before any run starts (scene, controller file, model)."""
    scene = load_scene(settings["scene"], _scene_overrides(settings))
    if scene.kind != "closed_loop":
        raise SpecError(
            f"scene kind '{scene.kind}' is not a closed-loop scene; allowed: kind = "
            '"closed_loop"',
            source=str(settings["scene"]),
            key="kind",
        )
    if settings.get("controller"):
        load_controller(settings["controller"], overrides_for(settings, "controller"))
    if scene.plant.fidelity.kind == "auto":
        check_auto(scene, settings.get("controller"))


def unavailable_metrics(settings: dict) -> dict[str, str]:
    """The metrics this run cannot produce, from its controller file.

    ``closed_loop_radius`` needs a linear law; the payload metrics a ``[payload]`` table.
    """
    from flexctrl.control import has_linear_law

    controller = settings.get("controller") or getattr(
        load_scene(settings["scene"], _scene_overrides(settings)), "controller", None
    )
    if not controller:
        return {}
    controller_settings = load_controller(controller, overrides_for(settings, "controller"))
    kind = controller_settings.kind
    missing = {}
    if getattr(controller_settings, "payload", None) is None:
        reason = "a controller without a [payload] table has no payload estimate"
        missing = {"payload_estimate_error": reason, "payload_estimate_time": reason}
    if not has_linear_law(kind):
        missing["closed_loop_radius"] = (
            f"a {kind} controller has no linear law, so no linear verdict (flexctrl.loop.verdict)"
        )
    return missing


def execute(settings: dict) -> RunOutput:
    """One closed-loop run from a settings dict (see :mod:`flexctrl.study.registry`).

    Metrics are flattened to scalars (``peak_torque_1`` ...); one that does not apply to the run
    is NaN with its reason in the output's ``notes``.  With them goes what the report needs to
    draw the run: ``window_start`` (s, the residual window's start) and the finite
    ``torque_limit_<k>`` (N m).  Trajectories (``t`` in s, ``e`` the tip's distance from
    its target in m, tip position ``tip_x``, ``tip_y`` in m, joint angles ``q<k>`` in rad,
    torques ``u<k>`` in N m, link tip deflections ``w<k>`` in m) are returned at the plant
    rate and decimated by the study.
    """
    scene = load_scene(settings["scene"], _scene_overrides(settings))
    cache = worker_scene_cache()
    shared, choosing = None, time.perf_counter()
    if settings.get("choice_from") is not None and scene.plant.fidelity.kind == "auto":
        shared = shared_choice(settings["choice_from"], cache)
    choosing = time.perf_counter() - choosing
    result = run_closed_loop_scene(
        scene,
        None,
        controller=settings.get("controller"),
        overrides=overrides_for(settings, "controller"),
        plots=False,
        on_divergence="record",
        cache=cache,
        choice=shared,
    )
    metrics: dict[str, float] = {}
    for key, value in result.summary["metrics"].items():
        if isinstance(value, list):
            metrics.update({f"{key}_{i + 1}": float(v) for i, v in enumerate(value)})
        else:
            metrics[key] = float(value)
    metrics["window_start"] = result.residual_window[0]
    for k, joint in enumerate(result.model.spec.joints, 1):
        if math.isfinite(joint.torque_limit):
            metrics[f"torque_limit_{k}"] = float(joint.torque_limit)
    if shared is not None:
        metrics["choice_time_s"] = choosing
        metrics["choice_shared"] = float(settings["choice_from"] != choice_settings(settings))
    traj = result.trajectory
    series = {
        "t": traj.time,
        "e": result.tip_error,
        "tip_x": traj.tip[:, 0],
        "tip_y": traj.tip[:, 1],
    }
    for i in range(traj.inputs.shape[1]):
        series[f"q{i + 1}"] = traj.states[:, i]
        series[f"u{i + 1}"] = traj.inputs[:, i]
        series[f"w{i + 1}"] = traj.deflections[:, i]
    notes = dict(result.summary.get("metric_notes", {}))
    if math.isnan(metrics.get("payload_estimate_time", 0.0)):
        notes["payload_estimate_time"] = "the payload estimate never stays within 0.2 kg"
    return RunOutput(metrics=metrics, trajectories=series, notes=notes)


def shared_choice(representative: dict, cache):
    """The fidelity choice of a group's representative run (its settings), made once per worker and
    kept.

    A choice that fails (e.g. :class:`~flexctrl.fidelity.ladder.ToleranceUnreachable`) is
    kept too and raised again for every member, so the group is judged once.
    """

    def build():
        scene = load_scene(representative["scene"], _scene_overrides(representative))
        try:
            return resolve_auto(
                scene,
                representative.get("controller"),
                overrides_for(representative, "controller"),
                cache,
            )[1]
        except FlexctrlError as exc:
            return exc

    value = cache.get("shared_choices", json.dumps(representative, sort_keys=True), build)
    if isinstance(value, Exception):
        raise value
    return value
