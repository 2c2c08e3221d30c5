"""Building a closed loop from a scene: plant and design models, the controller, its reference.

:func:`build_loop` is the one place a closed-loop scene becomes objects: the plant
(the scene's arm at the plant's fidelity), the design model (another payload, fidelity
or configuration when the scene says so), the controller designed on it and set to
track the scene's joint reference, the plant's sensors with the controller's noise
(:func:`flexctrl.loop.mismatch.plant_sensors`), the initial state and the divergence
monitor.  Models come from the caller's :class:`~flexctrl.scenes.cache.SceneCache`.
"""

from __future__ import annotations

import copy
import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.control import design
from flexctrl.control.reference_trajectory import ReferenceTrajectory
from flexctrl.errors import FlexctrlError, SolverError, SpecError
from flexctrl.linear import equilibrium
from flexctrl.loop.mismatch import plant_sensors
from flexctrl.loop.monitors import divergence_monitor
from flexctrl.loop.sampled import integrate_closed_loop, tip_positions
from flexctrl.scenes.arm_setup import initial_state, scene_arm
from flexctrl.scenes.cache import SceneCache
from flexctrl.spec.controller_reader import load_controller
from flexctrl.spec.fidelity import parse_fidelity

#: The model a controller is designed on when the plant is ``fidelity = "auto"`` and the scene names
#: no ``controller_fidelity``: the quickstart's plant and design model (two modes per link).
AUTO_DESIGN_FIDELITY = "amm:2"


def pin_design(scene):
    """The scene with its design model pinned when the plant's fidelity is ``auto``.

    The plant is what auto chooses; the controller must not change with it, so it is
    designed on ``controller_fidelity``, or :data:`AUTO_DESIGN_FIDELITY` when the scene
    gives none.  Other scenes are returned unchanged.
    """
    if scene.plant.fidelity.kind != "auto" or scene.controller_fidelity is not None:
        return scene
    return dataclasses.replace(scene, controller_fidelity=parse_fidelity(AUTO_DESIGN_FIDELITY))


@dataclass
class LoopSetup:
    """Everything a closed-loop run needs, built by :func:`build_loop`."""

    scene: Any
    plant_scene: Any
    arm: Any
    plant: Any
    design_arm: Any
    design_fidelity: Any
    design_q: tuple[float, ...]
    design_model: Any
    controller: Any
    settings: Any
    path: Path | None
    reference: Any
    sensors: Any
    x0: np.ndarray
    monitor: Any
    build_time_s: float
    #: What the designed controller depends on (the key of ``cache``'s "designs"; None for a
    #: designed controller).
    design_key: Any = None
    #: The scene's payload changes: ``(time s, plant, its sensors)`` (:func:`payload_plants`).
    changes: list = dataclasses.field(default_factory=list)

    @property
    def final_plant(self):
        """The plant the run ends on (after the last payload change)."""
        return self.changes[-1][1] if self.changes else self.plant

    @property
    def final_sensors(self):
        """The controller's sensors on :attr:`final_plant`."""
        return self.changes[-1][2] if self.changes else self.sensors


def design_scene_controller(scene, design_model, settings, path: str | Path, reference=None):
    """Design ``settings`` on ``design_model`` at the scene's design configuration, reset.

    The controller tracks the scene's path: ``reference``, the
    :class:`~flexctrl.control.reference_trajectory.ReferenceTrajectory` of the path on
    ``design_model`` when the caller keeps one
    (:meth:`~flexctrl.scenes.cache.SceneCache.reference`), else one built here.

    Raises
    ------
    SolverError
        When the design fails numerically (named with the controller file and the configuration).
    """
    design_q = tuple(scene.design_configuration)
    op = equilibrium(design_model, design_q)
    where = "the target" if scene.design_q is None else "the design configuration"
    try:
        ctrl = design(design_model, op, settings)
    except FlexctrlError:
        raise
    except (
        Exception
    ) as exc:  # numerical failures inside control/scipy/osqp become a clear, recorded error
        raise SolverError(
            f"designing the '{settings.kind}' controller ({path}) at {where} "
            f"{np.degrees(design_q).round(3).tolist()} deg failed: {type(exc).__name__}: {exc}"
        ) from exc
    if reference is None:
        reference = ReferenceTrajectory(design_model, scene.joint_reference(), scene.deflection)
    ctrl.set_reference(reference)
    ctrl.reset()
    return ctrl


def is_designed(controller) -> bool:
    """True for a designed controller (with ``step`` and ``sensors``), False for a path or None."""
    return hasattr(controller, "step") and hasattr(controller, "sensors")


def build_loop(
    scene,
    controller=None,
    overrides=(),
    cache: SceneCache | None = None,
) -> LoopSetup:
    """Build plant and design models (kept in ``cache``), design the controller, set its reference.

    ``scene`` must have a concrete plant fidelity (resolve ``auto`` first).  ``controller``
    is a controller file (default: the scene's), or a controller designed in Python
    (:func:`flexctrl.control.design`): it then keeps its own design model, payload and
    operating point, so the scene's ``design_payload``, ``controller_fidelity`` and
    ``design_configuration`` must be absent, and ``overrides`` empty.

    A controller designed from a file is kept in ``cache`` ("designs") under everything
    it depends on (design arm, fidelity, configuration, settings, the scene's joint
    path and deflection) and reset for each run, so the runs of a worker that differ
    only in the plant (payload, fidelity, step, noise) design once.  Its reference
    trajectory is kept in ``cache`` ("references") under the design model's description,
    the path and the deflection, so every controller designed on one model for one move
    shares its tables; the tables are compiled as the plant's ``solver.compile`` says
    (compiled unless switched off).
    """
    cache = SceneCache() if cache is None else cache
    start = time.perf_counter()
    plant_scene = scene.plant
    designed = is_designed(controller)
    path = None if designed else (controller or scene.controller)
    if not designed and path is None:
        raise SpecError(
            "no controller: give --controller FILE or the scene key 'controller'",
            source=scene.source,
            key="controller",
        )
    arm = scene_arm(plant_scene)
    if len(scene.target_q) != arm.n_links:
        raise SpecError(
            f"has {len(scene.target_q)} values; expected {arm.n_links} (one per joint)",
            source=scene.source,
            key="target.q",
        )
    plant = cache.model(arm, str(plant_scene.fidelity), plant_scene.modes, plant_scene.q0)
    design = (
        _designed_in_python(scene, controller, overrides, plant)
        if designed
        else _designed_from_file(scene, path, overrides, cache, arm, plant)
    )
    ctrl = design.controller
    sensors = ctrl.sensors if design.same else plant_sensors(plant, ctrl.sensors, design.q)
    return LoopSetup(
        scene,
        plant_scene,
        arm,
        plant,
        design.arm,
        design.fidelity,
        design.q,
        design.model,
        ctrl,
        design.settings,
        None if path is None else Path(path),
        scene.joint_reference(),
        sensors,
        initial_state(plant_scene, plant, arm),
        divergence_monitor(
            plant,
            arm,
            scene.start_q,
            scene.target_q,
            scene.divergence_deflection,
            scene.divergence_angle,
        ),
        time.perf_counter() - start,
        design.key,
        payload_plants(scene, arm, ctrl, design.q, cache),
    )


def payload_plants(scene, arm, ctrl, design_q, cache: SceneCache) -> list:
    """``(time, plant, sensors)`` of the scene's payload changes, each plant rebuilt with it."""
    plant_scene = scene.plant
    out = []
    for when, mass in scene.payload_changes:
        plant = cache.model(
            arm.with_payload(mass), str(plant_scene.fidelity), plant_scene.modes, plant_scene.q0
        )
        out.append((when, plant, plant_sensors(plant, ctrl.sensors, design_q)))
    return out


@dataclass(frozen=True)
class _Design:
    """A designed controller, reset and tracking the scene's path, and what it was designed on."""

    controller: Any
    settings: Any
    model: Any
    arm: Any
    fidelity: Any
    q: tuple[float, ...]
    #: Whether the design model is the plant (then the controller's own sensors read it).
    same: bool
    key: Any = None


def _designed_in_python(scene, ctrl, overrides, plant) -> _Design:
    """A controller from :func:`flexctrl.design`, set to track the scene's path on its own model."""
    design_model = _design_model_of(ctrl, scene, overrides)
    ctrl.set_reference(ReferenceTrajectory(design_model, scene.joint_reference(), scene.deflection))
    ctrl.reset()
    return _Design(
        controller=ctrl,
        settings=ctrl.settings,
        model=design_model,
        arm=design_model.spec,
        fidelity=design_model.fidelity,
        q=tuple(float(a) for a in ctrl.op.joints),
        same=design_model is plant,
    )


def _designed_from_file(scene, path, overrides, cache: SceneCache, arm, plant) -> _Design:
    """The controller file's design on the scene's design model, kept in ``cache`` and reset."""
    plant_scene = scene.plant
    settings = load_controller(path, overrides)
    compile = plant_scene.solver.get("compile")
    design_arm = arm if scene.design_payload is None else arm.with_payload(scene.design_payload)
    design_fidelity = scene.controller_fidelity or plant_scene.fidelity
    design_q = tuple(scene.design_configuration)
    same = (
        design_arm == arm
        and str(design_fidelity) == str(plant_scene.fidelity)
        and scene.design_q is None
    )
    design_model = (
        plant
        if same
        else cache.model(design_arm, str(design_fidelity), plant_scene.modes, design_q)
    )
    model_key = (
        design_arm,
        str(design_fidelity),
        plant_scene.modes,
        plant_scene.q0 if same else design_q,
    )
    path_ref = scene.joint_reference()
    key = (*model_key, design_q, settings, path_ref, scene.deflection, compile)
    ctrl = cache.get(
        "designs",
        key,
        lambda: design_scene_controller(
            scene,
            design_model,
            settings,
            path,
            cache.reference(*model_key, path_ref, scene.deflection, compile),
        ),
    )
    ctrl.reset()  # a design kept from an earlier run starts afresh (its reference table is kept)
    return _Design(ctrl, settings, design_model, design_arm, design_fidelity, design_q, same, key)


def _design_model_of(ctrl, scene, overrides):
    """The model a designed controller was designed on; the scene may not ask for another design."""
    for key, value in (
        ("design_payload", scene.design_payload),
        ("controller_fidelity", scene.controller_fidelity),
        ("design_configuration", scene.design_q),
    ):
        if value is not None:
            raise SpecError(
                "does not apply to a controller designed in Python (it keeps its own design "
                "model); allowed: no such key, or a controller file",
                source=scene.source,
                key=key,
            )
    if overrides:
        raise SpecError(
            f"controller overrides {list(overrides)} do not apply to a designed controller; "
            "allowed: none",
            key="overrides",
        )
    model = getattr(ctrl, "design_model", None)
    if model is None:
        raise SpecError(
            f"the {type(ctrl).__name__} has no design_model; allowed: a controller from "
            "flexctrl.design(model, op, settings), or a controller file",
            key="controller",
        )
    return model


def closed_loop_tip_path(
    scene,
    fidelity,
    dt: float,
    *,
    controller: str | Path | None = None,
    overrides=(),
    stride: int = 1,
    cache: SceneCache | None = None,
    keep: bool = False,
) -> dict[str, Any]:
    """The closed loop with the plant at ``fidelity`` and RK4 step ``dt`` (s): tip path and torques.

    Used by :func:`flexctrl.scenes.auto_closed_loop.choose_closed_loop_fidelity`.  A
    diverging run stops there (``diverged_at``, s).  The scene's ``controller_fidelity``
    (the design model) is kept, so only the plant changes with ``fidelity``.

    Returns
    -------
    dict
        ``time`` (s), ``tip`` (m, shape (T, 2)) and ``torque`` (N m, (T, n_u)) every
        ``stride`` plant steps; ``wall_time_s`` (the loop), ``build_time_s`` (models,
        design, compiling or loading the plant's step), ``omega_max`` (rad/s),
        ``diverged_at`` (s or None); with ``keep``, also ``run``: the whole run at the
        plant rate (``t``, ``X``, ``U``, ``meta`` of
        :func:`~flexctrl.loop.sampled.integrate_closed_loop` and the controller's
        ``stats``), integrated with stride 1 and subsampled, which keeps every other value
        the same.
    """
    fid = parse_fidelity(fidelity, key="fidelity")
    plant_scene = dataclasses.replace(scene.plant, fidelity=fid, dt=float(dt))
    setup = build_loop(dataclasses.replace(scene, plant=plant_scene), controller, overrides, cache)
    rng = np.random.default_rng(scene.seed) if scene.noise else None
    t, X, U, meta, _ = integrate_closed_loop(
        setup.plant,
        setup.controller,
        setup.x0,
        plant_scene.duration,
        float(dt),
        sensors=setup.sensors,
        rng=rng,
        compile=plant_scene.solver.get("compile"),
        monitor=setup.monitor,
        stop_on_divergence=True,
        stride=1 if keep else stride,
    )
    whole = (
        {"t": t, "X": X, "U": U, "meta": meta, "stats": copy.deepcopy(setup.controller.stats)}
        if keep
        else None
    )
    if keep:
        X, U = X[::stride], U[::stride]
        t = np.arange(X.shape[0]) * (float(dt) * stride)
    plant = setup.plant
    tip = tip_positions(plant, X, plant_scene.solver.get("compile"))
    divergence = meta.get("divergence")
    return {
        "time": t,
        "tip": tip,
        "torque": U,
        "wall_time_s": float(meta["wall_time_s"]),
        "build_time_s": setup.build_time_s + float(meta["setup_time_s"]),
        "omega_max": float(plant.omega_max),
        "diverged_at": None if divergence is None else float(divergence["time"]),
        **({"run": whole} if keep else {}),
    }
