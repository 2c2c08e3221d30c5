"""The pieces every arm scene is run with: the scene's arm, its initial state, one simulation.

:func:`scene_arm` loads the arm and applies the scene's payload, gravity and damping;
:func:`initial_state` builds ``x0``; :func:`simulate_arm_scene` builds the model at
the scene's fidelity (frozen modes at the initial configuration) and integrates.
Running a whole scene with its files is :func:`flexctrl.scenes.run_arm_scene.run_arm_scene`.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.dynamics.build import build_model
from flexctrl.errors import SpecError
from flexctrl.sim import get_integrator
from flexctrl.sim.trajectory import Trajectory
from flexctrl.spec.arm import ArmSpec, load_arm
from flexctrl.spec.arm_scene import ArmScene


@dataclass
class SceneResult:
    """What a scene run produced.

    Attributes
    ----------
    scene : Any
        The validated scene.
    trajectory : Trajectory
    summary : dict
        The content of ``summary.json``.
    files : list of pathlib.Path
        Files written (empty without an output folder).
    model : Any
        The built model.
    """

    scene: Any
    trajectory: Trajectory
    summary: dict[str, Any]
    files: list[Path] = field(default_factory=list)
    model: Any = None


def scene_arm(scene: ArmScene) -> ArmSpec:
    """The scene's arm: the model file with payload, gravity and damping overrides applied."""
    arm = load_arm(scene.model)
    if scene.payload is not None:
        arm = arm.with_payload(scene.payload)
    if scene.gravity is not None:
        arm = dataclasses.replace(arm, gravity=scene.gravity)
    if scene.axial_shortening is not None:
        arm = dataclasses.replace(arm, axial_shortening=scene.axial_shortening)
    if scene.axial_stretch is not None:
        arm = dataclasses.replace(arm, axial_stretch=scene.axial_stretch)
    if scene.zeta is not None:
        arm = dataclasses.replace(
            arm,
            links=tuple(dataclasses.replace(l, damping_ratios=(scene.zeta,)) for l in arm.links),
        )
    if scene.damping_form is not None:
        arm = dataclasses.replace(arm, damping_form=scene.damping_form)
    if arm.damping_form == "modal" and scene.zeta is not None:  # zeta of the coupled modes
        arm = dataclasses.replace(arm, damping_zeta=scene.zeta)
    if scene.friction is not None:
        friction = scene.friction * arm.n_links if len(scene.friction) == 1 else scene.friction
        if len(friction) != arm.n_links:
            raise SpecError(
                f"lists {len(friction)} values for {arm.n_links} joints; allowed: one value, or "
                "one per joint",
                source=scene.source,
                key="damping.friction",
            )
        arm = dataclasses.replace(
            arm,
            joints=tuple(dataclasses.replace(j, friction=b) for j, b in zip(arm.joints, friction)),
        )
    return arm


def initial_state(scene: ArmScene, model, arm: ArmSpec) -> np.ndarray:
    """``x0 = (q, qd)`` from the scene's joint angles, rates and elastic coordinates."""
    n = model.n_joints
    x0 = np.zeros(model.n_x)
    for key, values, offset in (("initial.q", scene.q0, 0), ("initial.qd", scene.qd0, model.n_q)):
        if values is None:
            continue
        if len(values) != n:
            raise SpecError(
                f"has {len(values)} values; expected {n} (one per joint)",
                source=scene.source,
                key=key,
            )
        x0[offset : offset + n] = values
    if scene.q0 is None:
        x0[:n] = arm.configuration
    names = list(model.coordinate_names)
    for name, value in scene.qf0.items():
        if name not in names:
            hint = difflib.get_close_matches(name, names[n:], n=1)
            extra = f" (did you mean '{hint[0]}'?)" if hint else ""
            raise SpecError(
                f"is not a coordinate of the model at fidelity '{model.fidelity}'; "
                f"allowed: {', '.join(names[n:]) or 'none (rigid model)'}{extra}",
                source=scene.source,
                key=f"initial.qf.{name}",
            )
        x0[names.index(name)] = value
    return x0


def simulate_arm_scene(scene: ArmScene, *, model=None, integrator=None, **integrator_options: Any):
    """Simulate an arm scene at its own fidelity, integrator and step, writing nothing.

    Parameters
    ----------
    scene
        A ``kind = "arm"`` scene with a concrete fidelity (not ``auto``).
    model
        The built model, when the caller has it (e.g. from a cache); built here otherwise.
    integrator
        A set-up :class:`~flexctrl.sim.integrator.Integrator` for ``model`` at ``scene.dt``,
        when the caller has one.
    **integrator_options
        Passed to the integrator class (e.g. ``compile=False``).

    Returns
    -------
    (Trajectory, Model, ArmSpec)
    """
    arm = scene_arm(scene)
    reference_q = scene.q0 if scene.q0 is not None else None
    if reference_q is not None and len(reference_q) != arm.n_links:
        raise SpecError(
            f"has {len(reference_q)} values; expected {arm.n_links} (one per joint)",
            source=scene.source,
            key="initial.q",
        )
    if model is None:
        model = build_model(arm, scene.fidelity, modes=scene.modes, reference_q=reference_q)
    x0 = initial_state(scene, model, arm)
    if scene.input.kind != "none" and scene.input.joint > model.n_joints:
        raise SpecError(
            f"value {scene.input.joint} is out of range; allowed: 1 to {model.n_joints}",
            source=scene.source,
            key="input.joint",
        )
    n_steps = max(1, int(math.ceil(scene.duration / scene.dt - 1e-9)))
    u = scene.input.samples(n_steps, scene.dt, model.n_joints)
    if integrator is None:
        cls = get_integrator(scene.integrator)
        integrator = cls(model, scene.dt, **{**scene.solver, **integrator_options})
    trajectory = integrator.run(x0, scene.duration, u=u)
    trajectory.meta["scene"] = scene.name
    return trajectory, model, arm


def model_facts(model) -> dict[str, Any]:
    info = model.info or {}
    facts = {
        "name": model.name,
        "coordinates": list(model.coordinate_names),
        "omega_max_rad_s": float(model.omega_max),
    }
    for key in ("build_time_s", "modes", "locked_frequencies_rad_s", "link_frequencies_rad_s"):
        if key in info:
            value = info[key]
            facts[key] = value.tolist() if isinstance(value, np.ndarray) else value
    return facts
