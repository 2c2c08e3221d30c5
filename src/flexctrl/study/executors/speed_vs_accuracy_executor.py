"""The ``speed_vs_accuracy`` study executor: one run = one scene x payload x configuration x method.

Settings (besides the study's ``scene``, ``payload``, ``configuration``, ``controller``)
come as *scene* keys of the study file, so they can be fixed in ``[set]`` or be a grid
axis without any change to the study machinery; the executor removes them from the
scene's overrides before the scene file is validated:

``scene.method``
    The method to time and judge (:func:`flexctrl.analysis.simulation_methods.parse_method`),
    e.g. ``"amm:2/rk4@1ms"``.  Required.
``scene.reference``
    The reference method (default ``"fem:8/rk4@stable"``).
``scene.reference_meshes``
    Other meshes run with the reference's integrator as convergence evidence
    (default ``["fem:4"]``).
``scene.repeats``
    Timed repetitions of the candidate; ``wall_per_sim_s`` is their median (default 3;
    fewer when the runs so far took more than :data:`REPEAT_BUDGET_S` together).
``scene.horizon``
    Simulated time compared (s): the first ``horizon`` seconds of the scene (default:
    the scene's duration).  The scene file's own duration is left alone, so its checks
    (a closed-loop scene's residual window after the move) still hold.

Scenes: ``kind = "arm"`` (torque from the scene's ``[input]``) and
``kind = "closed_loop"`` (the scene's or the study's controller, designed once on the
scene's own fidelity and payload and then run, unchanged, on every candidate plant;
its sensors must exist on every plant, e.g. joints and link-tip deflections, not the
full state).  The scene's ``fidelity``, ``modes``, ``integrator`` and ``dt`` are those
of the method; ``[initial.qf]`` is dropped (elastic coordinates belong to one model
family: ``qf31`` is no coordinate of ``fem:4`` or ``rigid``), so every model starts
undeformed; measurement noise is off.

Metrics: ``tip_error_rms``, ``tip_error_max`` (m, against the reference, on its 1 ms
samples), ``wall_per_sim_s`` (s of integration per simulated s, median of repeats),
``wall_per_sim_s_spread`` (max minus min over repeats, same unit), ``setup_s``
(build and compile, s; compiled code is cached on disk, so a rerun shows the load
time), ``step_s`` (the fixed step, or the mean internal step of adaptive methods;
left out for implicit solve_ivp methods, whose step count is not reported),
``omega_max`` (rad/s), ``n_states``, ``tip_travel`` (m: largest distance of the
reference tip from its start, the scale of the errors), ``ref_wall_per_sim_s`` and
the reference's convergence evidence ``ref_step2_rms``/``_max`` (half step) and
``ref_<mesh>_rms``/``_max`` per mesh (m).

The report section (:func:`report_sections`) draws error against cost on log axes,
one point per method (medians over the runs of a scene, and over all runs), marks
the Pareto front, writes ``pareto.csv`` and tabulates the same numbers.
"""

from __future__ import annotations

import dataclasses
import json
import math
import statistics
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.analysis.accuracy import Reference, cached_reference, compute_reference
from flexctrl.analysis.simulation_methods import OUTPUT_DT, Method, parse_method
from flexctrl.analysis.steppers import MethodRun, make_stepper, run_closed_loop, run_open_loop
from flexctrl.errors import SpecError
from flexctrl.spec.shipped import data_root

#: Scene keys read by this executor (removed before the scene file is validated).
from flexctrl.study.executors.speed_accuracy_report import report_sections as report_sections
from flexctrl.study.outputs import (
    RunOutput,
    overrides_for,
    per_worker_cache,
    worker_scene_cache,
)

OWN_KEYS = ("method", "reference", "reference_meshes", "repeats", "horizon")
DEFAULT_REFERENCE = "fem:8/rk4@stable"
DEFAULT_MESHES = ("fem:4",)
DEFAULT_REPEATS = 3
# : Repeats stop once the timed runs of one candidate add up to this (s): a long run is its own
# average.
REPEAT_BUDGET_S = 3.0
#: Right-hand-side evaluations per step of the explicit solve_ivp methods (for their mean step).
_RK_STAGES = {"RK45": 6, "RK23": 3, "DOP853": 12}


@dataclasses.dataclass(frozen=True)
class RunPlan:
    """Everything one run needs, parsed from the settings (hashable)."""

    scene_path: str
    scene_digest: str | None
    scene_overrides: tuple[str, ...]
    model_path: str
    model_digest: str | None
    payload: float
    q0_deg: tuple[float, ...]
    controller: str | None
    controller_digest: str | None
    controller_overrides: tuple[str, ...]
    method: Method
    reference: Method
    meshes: tuple[str, ...]
    repeats: int
    horizon: float | None


def _split_overrides(settings: Mapping[str, Any]) -> tuple[dict[str, Any], list[str]]:
    from flexctrl.spec.overrides import parse_value

    own: dict[str, Any] = {}
    rest: list[str] = []
    for item in overrides_for(settings, "scene"):
        key, _, value = item.partition("=")
        if key.strip() in OWN_KEYS:
            own[key.strip()] = parse_value(value.strip())
        else:
            rest.append(item)
    return own, rest


def plan_from_settings(settings: Mapping[str, Any]) -> RunPlan:
    """Parse and validate one run's settings.

    Raises
    ------
    SpecError
        Naming the key (``scene.method`` ...), the value and what is allowed.
    """
    source = str(settings.get("scene"))
    own, rest = _split_overrides(settings)
    if settings.get("fidelity") is not None:
        raise SpecError(
            f"value {settings['fidelity']!r} is not used here; allowed: leave 'fidelity' out and "
            "give the model in "
            "scene.method (e.g. 'amm:2/rk4@1ms')",
            source=source,
            key="fidelity",
        )
    if "method" not in own:
        raise SpecError(
            'missing: the method to judge, e.g. "scene.method" = "amm:2/rk4@1ms" (fixed in [set] '
            "or a [grid] axis)",
            source=source,
            key="scene.method",
        )
    method = parse_method(own["method"], source=source, key="scene.method")
    reference = parse_method(
        own.get("reference", DEFAULT_REFERENCE), source=source, key="scene.reference"
    )
    if reference.fidelity.split(":")[0] != "fem":
        raise SpecError(
            f"value {reference.label!r} is not allowed; allowed: a finite-element reference "
            "'fem:N/...'",
            source=source,
            key="scene.reference",
        )
    meshes = own.get("reference_meshes", list(DEFAULT_MESHES))
    if not isinstance(meshes, list) or not all(
        isinstance(m, str) and m.startswith("fem:") for m in meshes
    ):
        raise SpecError(
            f"value {meshes!r} is not allowed; allowed: a list of finite-element fidelities, "
            'e.g. ["fem:4"]',
            source=source,
            key="scene.reference_meshes",
        )
    for m in meshes:
        parse_method(f"{m}/rk4@stable", source=source, key="scene.reference_meshes")
    repeats = own.get("repeats", DEFAULT_REPEATS)
    if isinstance(repeats, bool) or not isinstance(repeats, int) or not 1 <= repeats <= 50:
        raise SpecError(
            f"value {repeats!r} is not allowed; allowed: an integer from 1 to 50",
            source=source,
            key="scene.repeats",
        )
    horizon = own.get("horizon")
    if horizon is not None and (
        isinstance(horizon, bool)
        or not isinstance(horizon, (int, float))
        or not 0.01 <= horizon <= 100
    ):
        raise SpecError(
            f"value {horizon!r} is not allowed; allowed: a number of seconds from 0.01 to 100",
            source=source,
            key="scene.horizon",
        )
    digests = settings.get("digests", {})
    return RunPlan(
        scene_path=str(settings["scene"]),
        scene_digest=digests.get("scene"),
        scene_overrides=tuple(rest),
        model_path=str(settings["model"]),
        model_digest=digests.get("model"),
        payload=float(settings["payload"]),
        q0_deg=tuple(float(a) for a in settings["q0_deg"]),
        controller=settings.get("controller"),
        controller_digest=digests.get("controller"),
        controller_overrides=tuple(overrides_for(settings, "controller")),
        method=method,
        reference=reference,
        meshes=tuple(meshes),
        repeats=repeats,
        horizon=None if horizon is None else float(horizon),
    )


@per_worker_cache(maxsize=16)
def _scene(plan_scene: tuple) -> Any:
    """The scene with the run's model, payload and configuration; ``[initial.qf]`` dropped."""
    from flexctrl.spec.overrides import apply_overrides
    from flexctrl.spec.reader import read_toml
    from flexctrl.spec.scene import scene_from_document

    path, _digest, overrides, model, payload, q0 = plan_scene
    extra = [
        f"model={json.dumps(model)}",
        f"payload={payload!r}",
        "initial.q=[" + ", ".join(repr(a) for a in q0) + "]",
    ]
    doc = apply_overrides(read_toml(path), [*extra, *overrides], source=f"{path} (overrides)")
    doc.get("initial", {}).pop("qf", None)
    for key in ("integrator", "solver"):
        doc.pop(key, None)  # the method decides
    scene = scene_from_document(doc, path, Path(path).resolve().parent)
    if scene.kind not in ("arm", "closed_loop"):
        raise SpecError(
            f"scene kind '{scene.kind}' is not allowed; allowed: 'arm', 'closed_loop'",
            source=path,
            key="kind",
        )
    return scene


def _plan_scene(plan: RunPlan) -> tuple:
    return (
        plan.scene_path,
        plan.scene_digest,
        plan.scene_overrides,
        plan.model_path,
        plan.payload,
        plan.q0_deg,
    )


def _plant_scene(scene):
    return scene.plant if scene.kind == "closed_loop" else scene


def _model(arm, fidelity: str, modes: str, q0: tuple[float, ...]):
    return worker_scene_cache().model(arm, fidelity, modes, q0)


@per_worker_cache(maxsize=24)
def _stepper(arm, method: Method, q0: tuple[float, ...]):
    return make_stepper(_model(arm, method.fidelity, method.modes, q0), method, OUTPUT_DT)


@per_worker_cache(maxsize=8)
def _controller(
    plan_scene: tuple,
    controller: str | None,
    controller_digest: str | None,
    overrides: tuple[str, ...],
):
    """Controller designed once on the scene's own fidelity (or ``controller_fidelity``) and payload
    (or ``design_payload``) at its design configuration, tracking the scene's reference path, as
    :func:`flexctrl.scenes.run_closed_loop_scene.run_closed_loop_scene` does; returns it and the
    design configuration (rad)."""
    from flexctrl.scenes.arm_setup import scene_arm
    from flexctrl.scenes.loop_setup import design_scene_controller
    from flexctrl.spec.controller_reader import load_controller

    scene = _scene(plan_scene)
    path = controller or scene.controller
    if path is None:
        raise SpecError(
            "no controller: give the study's 'controller' or the scene key 'controller'",
            source=scene.source,
            key="controller",
        )
    settings = load_controller(path, overrides)
    arm = scene_arm(scene.plant)
    design_arm = arm if scene.design_payload is None else arm.with_payload(scene.design_payload)
    fidelity = scene.controller_fidelity or scene.plant.fidelity
    design_q = tuple(scene.design_configuration)
    same = design_arm == arm and str(fidelity) == str(scene.plant.fidelity)
    model = _model(
        design_arm, str(fidelity), scene.plant.modes, scene.plant.q0 if same else design_q
    )
    ctrl = design_scene_controller(scene, model, settings, path)
    if ctrl.sensors.kinds == ("state",):
        raise SpecError(
            f"controller '{path}' measures the full state, which only a plant of its own design "
            "model has; "
            'allowed here: sensors that every model has, e.g. outputs = ["joints", "deflection"]',
            source=str(path),
            key="sensors.outputs",
        )
    return ctrl, design_q


def simulate_method(plan: RunPlan, method: Method) -> tuple[MethodRun, Any]:
    """Run ``method`` on the plan's scene once; returns the run and the model."""
    from flexctrl.loop.mismatch import plant_sensors
    from flexctrl.scenes.arm_setup import initial_state, scene_arm

    key = _plan_scene(plan)
    scene = _scene(key)
    plant = _plant_scene(scene)
    arm = scene_arm(plant)
    stepper = _stepper(arm, method, plant.q0)
    model = stepper.model
    x0 = initial_state(plant, model, arm)
    duration = plant.duration if plan.horizon is None else min(plant.duration, plan.horizon)
    if scene.kind == "closed_loop":
        ctrl, design_q = _controller(
            key, plan.controller, plan.controller_digest, plan.controller_overrides
        )
        sensors = plant_sensors(model, ctrl.sensors, design_q)
        return run_closed_loop(stepper, x0, ctrl, sensors, duration), stepper
    n = max(1, int(math.ceil(duration / OUTPUT_DT - 1e-9)))
    torque = plant.input.samples(n, OUTPUT_DT, model.n_u)
    return run_open_loop(stepper, x0, torque), stepper


def _reference_key(plan: RunPlan) -> dict[str, Any]:
    return {
        "scene": plan.scene_path,
        "scene_digest": plan.scene_digest,
        "overrides": list(plan.scene_overrides),
        "model_digest": plan.model_digest,
        "payload": plan.payload,
        "q0_deg": list(plan.q0_deg),
        "controller": plan.controller,
        "controller_digest": plan.controller_digest,
        "controller_overrides": list(plan.controller_overrides),
        "reference": plan.reference.label,
        "meshes": list(plan.meshes),
        "output_dt": OUTPUT_DT,
        "horizon": plan.horizon,
    }


@per_worker_cache(maxsize=16)
def _reference(plan_ref: RunPlan) -> tuple[Reference, str, bool]:
    ref, path, hit = cached_reference(
        _reference_key(plan_ref),
        lambda: compute_reference(
            lambda m: simulate_method(plan_ref, m)[0], plan_ref.reference, plan_ref.meshes
        ),
    )
    return ref, str(path), hit


def check_settings(settings: dict) -> None:
    """Validate one run before the study starts: the executor's keys, the scene with its overrides,
    the controller."""
    plan = plan_from_settings(settings)
    scene = _scene(_plan_scene(plan))
    if scene.kind == "closed_loop":
        from flexctrl.spec.controller_reader import load_controller

        path = plan.controller or scene.controller
        if path is None:
            raise SpecError(
                "closed-loop scene without a controller; allowed: the study's 'controller' or "
                "the scene key",
                source=scene.source,
                key="controller",
            )
        ctrl = load_controller(path, plan.controller_overrides)
        per = float(ctrl.sample_time) / OUTPUT_DT
        if abs(per - round(per)) > 1e-9 * per or round(per) < 1:
            raise SpecError(
                f"value {ctrl.sample_time!r} s is not allowed; allowed: a whole number of the "
                f"{OUTPUT_DT:g} s comparison "
                'samples, e.g. "controller.sample_time" = 0.01 in the study\'s [set]',
                source=str(path),
                key="sample_time",
            )


def execute(settings: dict) -> RunOutput:
    """One run (see the module docstring)."""
    from flexctrl.sim.tip_error import tip_error

    plan = plan_from_settings(settings)
    ref_plan = dataclasses.replace(plan, method=plan.reference, repeats=1)
    ref, _path, _hit = _reference(ref_plan)
    walls, first, stepper = [], None, None
    for _ in range(plan.repeats):
        run, stepper = simulate_method(plan, plan.method)
        walls.append(run.wall_s)
        if first is None:
            first = run
        if sum(walls) > REPEAT_BUDGET_S:
            break
    assert first is not None and stepper is not None
    duration = float(first.time[-1] - first.time[0])
    err = tip_error(ref.time, ref.tip, first.time, first.tip)
    distance = np.linalg.norm(
        np.column_stack([np.interp(ref.time, first.time, first.tip[:, k]) for k in range(2)])
        - ref.tip,
        axis=1,
    )
    model = stepper.model
    step = stepper.step_s
    steps = first.counters.get("internal_steps")
    if not steps and plan.method.integrator == "scipy" and plan.method.variant in _RK_STAGES:
        steps = first.counters.get("rhs_evaluations", 0) / _RK_STAGES[plan.method.variant]
    if steps:
        step = duration / steps
    metrics: dict[str, float] = {
        "tip_error_rms": err.rms,
        "tip_error_max": err.max,
        "wall_per_sim_s": statistics.median(walls) / duration,
        "wall_per_sim_s_spread": (max(walls) - min(walls)) / duration,
        "repeats_done": float(len(walls)),
        "setup_s": stepper.setup_s,
        "omega_max": float(model.omega_max),
        "n_states": float(model.n_x),
        "tip_travel": float(np.max(np.linalg.norm(ref.tip - ref.tip[0], axis=1))),
        "ref_wall_per_sim_s": ref.wall_s / duration,
    }
    if math.isfinite(step):
        metrics["step_s"] = step  # unknown for implicit solve_ivp methods
    for name, check in ref.checks.items():
        tag = "step2" if name == "step/2" else name.replace(":", "")
        metrics[f"ref_{tag}_rms"] = check["rms"]
        metrics[f"ref_{tag}_max"] = check["max"]
    return RunOutput(
        metrics=metrics,
        trajectories={
            "t": ref.time,
            "tip_error": distance,
            "tip_x": np.interp(ref.time, first.time, first.tip[:, 0]),
            "tip_y": np.interp(ref.time, first.time, first.tip[:, 1]),
        },
    )


def mesh_convergence(
    scene: str | Path,
    meshes: tuple[str, ...] = ("fem:4", "fem:8", "fem:12", "fem:16"),
    *,
    payload: float = 2.0,
    q0_deg: tuple[float, ...] = (0.0, 0.0, 0.0),
    horizon: float = 1.0,
    model: str | Path | None = None,
) -> dict[str, Any]:
    """Tip distances (m) between successive meshes, RK4 at each mesh's stable step: the evidence
    beyond the study's checks.

    For ``docs/explanation/speed-and-accuracy.md`` (too slow to repeat for every case of the study:
    fem:16 compiles for minutes).  Returns ``{"runs": {mesh: {"wall_per_sim_s", "step_s"}},
    "pairs": {"fem:4-fem:8": {"rms", "max"}, ...}, "against_finest": {...}}``.

    Examples
    --------
    ``python -c "from flexctrl.study.executors.speed_vs_accuracy_executor import mesh_convergence as
    m; print(m('studies/scenes/bangbang.toml'))"``
    """
    from flexctrl.sim.tip_error import tip_error

    root = data_root()
    settings: dict[str, Any] = {
        "scene": str(Path(scene).resolve()),
        "model": str(model or root / "models" / "subedi3link.toml"),
        "controller": None,
        "payload": float(payload),
        "q0_deg": list(q0_deg),
        "fidelity": None,
        "overrides": [
            f'scene.method="{meshes[-1]}/rk4@stable"',
            f"scene.horizon={float(horizon)!r}",
        ],
        "digests": {},
    }
    plan = plan_from_settings(settings)
    runs: dict[str, MethodRun] = {}
    out: dict[str, Any] = {"runs": {}, "pairs": {}, "against_finest": {}}
    for mesh in meshes:
        run, stepper = simulate_method(plan, parse_method(f"{mesh}/rk4@stable"))
        runs[mesh] = run
        out["runs"][mesh] = {
            "wall_per_sim_s": run.wall_s / float(run.time[-1]),
            "step_s": stepper.step_s,
            "setup_s": stepper.setup_s,
        }
    for a, b in zip(meshes[:-1], meshes[1:]):
        e = tip_error(runs[b].time, runs[b].tip, runs[a].time, runs[a].tip)
        out["pairs"][f"{a}-{b}"] = {"rms": e.rms, "max": e.max}
    finest = runs[meshes[-1]]
    for a in meshes[:-1]:
        e = tip_error(finest.time, finest.tip, runs[a].time, runs[a].tip)
        out["against_finest"][a] = {"rms": e.rms, "max": e.max}
    return out
