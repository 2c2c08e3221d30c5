"""Running the finite-element scenes (``kind = "sliding_beam"``, ``"rp_arm"``, ``"telescoping"``).

The scenes are the validated descriptions of :mod:`flexctrl.spec.fem_scene`
(:class:`~flexctrl.spec.fem_scene.SlidingBeamScene`,
:class:`~flexctrl.spec.fem_scene.RPArmScene`, :class:`~flexctrl.spec.fem_scene.TelescopingScene`);
:func:`run_scene` runs one (the runner of :data:`flexctrl.scenes.scene_runners.SCENE_RUNNERS`),
:func:`run_fem_scene` reads a document and runs it.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.spec.fem_scene import (
    FemScene,
    RPArmScene,
    SlidingBeamScene,
    TelescopingScene,
    read_fem_scene,
)
from flexctrl.spec.fidelity import Fidelity

#: The keywords :func:`run_scene` takes besides the scene and the output folder.
RUN_OPTIONS = ("plots", "fidelity")


def _integration(scene: FemScene) -> dict[str, Any]:
    """The Newmark + Baumgarte keywords every simulate function takes."""
    return dict(
        gamma=scene.gamma,
        beta=scene.beta,
        alpha=scene.alpha,
        delta=scene.delta,
        axial_shortening=scene.axial_shortening,
        max_violation=scene.max_violation,
    )


def _simulate(scene: FemScene):
    """Run the validated scene; returns (result, extra columns, model facts)."""
    if isinstance(scene, SlidingBeamScene):
        return _simulate_sliding_beam(scene)
    if isinstance(scene, TelescopingScene):
        return _simulate_telescoping(scene)
    if isinstance(scene, RPArmScene):
        return _simulate_rp_arm(scene)
    raise TypeError(
        f"{type(scene).__name__} is not a finite-element scene; allowed: SlidingBeamScene, "
        "RPArmScene, "
        "TelescopingScene (from read_fem_scene)"
    )


def _simulate_sliding_beam(scene: SlidingBeamScene):
    # each finite-element family loads only when a scene of it runs
    from flexctrl.dynamics.fem.sliding_beam import SlidingBeamCase, simulate_sliding_beam

    case = SlidingBeamCase(
        scene.name,
        C1=scene.C1,
        C2=scene.C2,
        T=scene.T,
        tracked_end=scene.tracked_end,
        driven_end=scene.driven_end,
        L=scene.L,
        rho=scene.rho,
        EI=scene.EI,
        D=scene.D,
        tip_deflection=scene.tip_deflection,
    )
    res = simulate_sliding_beam(
        case, scene.n_elements, dt=scene.dt, duration=scene.duration, **_integration(scene)
    )
    return res, {}, {"ndof": int(res.q.shape[1])}


def _rp_motion(scene: RPArmScene | TelescopingScene):
    """The prescribed motion of Eq 57: ``W(t)`` and the housing angle ``theta(t)``."""
    # loaded only when a scene of this family runs
    from flexctrl.dynamics.fem.moving_frame import RPMotion

    return RPMotion(
        C1=scene.C1,
        C2=scene.C2,
        T=scene.T,
        theta0=math.radians(scene.theta0_deg),
        dtheta=math.radians(scene.rotation_deg),
    )


def _simulate_rp_arm_partial(scene: RPArmScene):
    """The R-P arm with its motion prescribed, partial coupling (Eq 42)."""
    # loaded only when a scene of this family runs
    from flexctrl.dynamics.fem.rp_arm import simulate_rp_arm

    res = simulate_rp_arm(
        scene.model_spec,
        _rp_motion(scene),
        scene.n_elements,
        dt=scene.dt,
        duration=scene.duration,
        driven_end=scene.driven_end,
        tracked_end=scene.tracked_end,
        initial=scene.initial,
        tip_deflection=scene.tip_deflection,
        **_integration(scene),
    )
    return res, {"theta": res.theta, "tip_X": res.tip_world[:, 0], "tip_Y": res.tip_world[:, 1]}


def _simulate_rp_arm_full(scene: RPArmScene):
    """The R-P arm in full coupling (Eq 43): its motion, or its torque and force, prescribed."""
    # loaded only when a scene of this family runs
    from flexctrl.dynamics.fem.rp_arm_full import RPForces, simulate_rp_arm_full

    drive = scene.drive
    drives = (
        RPForces.sine(
            drive.torque_amplitude,
            drive.force_amplitude,
            scene.T,
            theta0=math.radians(scene.theta0_deg),
            W0=scene.C1,
        )
        if drive.kind == "force"
        else _rp_motion(scene)
    )
    res = simulate_rp_arm_full(
        scene.model_spec,
        drives,
        scene.n_elements,
        dt=scene.dt,
        duration=scene.duration,
        tracked_end=scene.tracked_end,
        **_integration(scene),
    )
    extra = {"theta": res.theta, "tip_X": res.tip_world[:, 0], "tip_Y": res.tip_world[:, 1]}
    return res, extra | {"torque": res.torque, "force": res.force}


def _simulate_rp_arm(scene: RPArmScene):
    spec = scene.model_spec
    if scene.drive.coupling == "partial":
        res, extra = _simulate_rp_arm_partial(scene)
    else:
        res, extra = _simulate_rp_arm_full(scene)
    facts = {
        "ndof": int(res.q.shape[1]),
        "support_inner_m": spec.support_inner,
        "support_outer_m": spec.support_outer,
        "link": {
            "length_m": spec.length,
            "mass_per_length_kg_m": spec.mass_per_length,
            "EI_N_m2": spec.EI,
        },
        "payload_kg": spec.payload_mass,
        "gravity_m_s2": list(spec.gravity),
    }
    return res, extra, facts


def _simulate_telescoping(scene: TelescopingScene):
    # loaded only when a scene of this family runs
    from flexctrl.dynamics.fem.telescoping import simulate_telescoping

    spec = scene.model_spec
    res = simulate_telescoping(
        spec,
        _rp_motion(scene),
        scene.n_elements,
        scene.n_elements,
        dt=scene.dt,
        duration=scene.duration,
        tracked_end=scene.tracked_end,
        **_integration(scene),
    )
    extra = {
        "theta": res.theta,
        "tip_X": res.tip_world[:, 0],
        "tip_Y": res.tip_world[:, 1],
        "outer_tip_y": res.outer_tip_y,
    }
    facts = {
        "ndof": int(res.q.shape[1]),
        "hub_radius_m": spec.hub_radius,
        "outer": dataclasses.asdict(spec.outer),
        "inner": dataclasses.asdict(spec.inner),
        "contacts": [dataclasses.asdict(c) for c in spec.contacts],
        "payload_kg": spec.payload_mass,
        "gravity_m_s2": list(spec.gravity),
    }
    return res, extra, facts


def _plot(path: Path, res, scene: FemScene, extra: dict[str, np.ndarray]) -> None:
    # matplotlib loads only when a figure is drawn
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 5.5), layout="constrained")
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    ax1.plot(res.t, 1e3 * res.tip_y)
    ax1.set_ylabel(f"tip_y at {scene.tracked_end} (mm)")
    ax1.set_title(
        f"{scene.name}: {scene.kind}, {scene.n_elements} elements, dt = {scene.dt:g} s, "
        f"axial shortening {'on' if scene.axial_shortening else 'off'}",
        fontsize=9,
    )
    if "outer_tip_y" in extra:
        ax1.plot(res.t, 1e3 * extra["outer_tip_y"], label="outer link mouth")
        ax1.lines[0].set_label(f"inner link {scene.tracked_end}")
        ax1.legend(loc="best", fontsize=8)
    ax1.grid(True, alpha=0.3)
    ax2.plot(res.t, res.W, label="W (m)")
    if "theta" in extra:
        ax2.plot(res.t, extra["theta"], label="theta (rad)")
    ax2.set_xlabel("t (s)")
    ax2.legend(loc="best", fontsize=8)
    if "torque" in extra:
        ax3 = ax2.twinx()
        ax3.plot(res.t, extra["torque"], "C3--", lw=0.8, label="torque (N m)")
        ax3.plot(res.t, extra["force"], "C4:", lw=0.8, label="force (N)")
        ax3.set_ylabel("torque (N m), force (N)")
        ax3.legend(loc="lower right", fontsize=8)
    ax2.grid(True, alpha=0.3)
    fig.savefig(path, dpi=110)


def _run(scene: FemScene, out_dir: Path | None) -> dict:
    """Simulate ``scene`` and (with ``out_dir``) write its files; returns the summary."""
    start = time.perf_counter()
    res, extra, facts = _simulate(scene)
    wall = time.perf_counter() - start
    simulated = float(res.t[-1] - res.t[0])
    summary: dict[str, Any] = {
        "scene": scene.settings(),
        "source": scene.source,
        "kind": scene.kind,
        "integrator": "newmark + baumgarte (flexctrl.dynamics.fem.newmark_dae)",
        "n_elements": scene.n_elements,
        "dt": float(res.dt),
        "n_steps": int(res.t.size - 1),
        "duration_s": simulated,
        "wall_time_s": wall,
        "integration_wall_time_s": float(res.wall_time),
        "wall_time_per_simulated_s": wall / simulated if simulated > 0 else math.nan,
        "peak_abs_tip_y_m": float(np.max(np.abs(res.tip_y))),
        "final_tip_y_m": float(res.tip_y[-1]),
        "max_phi_violation_m": float(np.max(res.phi_violation)),
        "max_phidot_violation_m_s": float(np.max(res.phidot_violation)),
        "model": facts,
        "status": "ok",
        "files": [],
    }
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        columns = {
            "t": res.t,
            "W": res.W,
            "tip_y": res.tip_y,
            "phi_max": res.phi_violation,
            "phidot_max": res.phidot_violation,
            **extra,
        }
        data = np.column_stack(list(columns.values()))
        csv = out / "trajectory.csv"
        np.savetxt(csv, data, delimiter=",", header=",".join(columns), comments="", fmt="%.12g")
        files = [csv]
        if scene.plots:
            png = out / "tip.png"
            _plot(png, res, scene, extra)
            files.append(png)
        summary["files"] = [str(p) for p in files] + [str(out / "summary.json")]
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary


def run_fem_scene(
    document: dict, source: str, out_dir: Path | None, fidelity: Fidelity | str | None = None
) -> dict:
    """Read, simulate and (with ``out_dir``) write a finite-element scene document.

    Parameters
    ----------
    document
        The parsed scene (``--set`` overrides already applied).
    source
        Its file name (for error messages and relative model paths).
    out_dir
        Folder for ``trajectory.csv``, ``summary.json``, ``tip.png`` (created); None writes nothing.
    fidelity
        ``fem:N`` replaces ``n_elements``; any other fidelity is a :class:`SpecError`.

    Returns
    -------
    dict
        The summary (also written as ``summary.json``).

    Examples
    --------
    >>> from flexctrl.spec.reader import read_toml
    >>> doc = read_toml("studies/scenes/bk_fast_push.toml")
    >>> doc["duration"] = 0.05
    >>> run_fem_scene(doc, "studies/scenes/bk_fast_push.toml", None)["n_steps"]
    50
    """
    return _run(read_fem_scene(document, source).with_fidelity(fidelity), out_dir)


@dataclasses.dataclass
class FemSceneResult:
    """What :func:`run_scene` produced: the scene as run (overrides applied), ``summary.json``'s
    content and the files written."""

    scene: FemScene
    summary: dict
    files: list[Path]


def run_scene(
    scene: FemScene,
    out: str | Path | None = None,
    *,
    plots: bool | None = None,
    fidelity: Fidelity | str | None = None,
    **unknown: Any,
) -> FemSceneResult:
    """Run a finite-element scene (the runner of its kinds in ``SCENE_RUNNERS``).

    Parameters
    ----------
    scene
        From :func:`flexctrl.spec.fem_scene.read_fem_scene` or
        :func:`flexctrl.spec.scene.load_scene`.
    out
        Folder for ``trajectory.csv``, ``summary.json`` and ``tip.png``; None writes nothing.
    plots
        Overrides the scene's ``plots`` (None keeps it).
    fidelity
        ``"fem:N"`` (or a :class:`~flexctrl.spec.fidelity.Fidelity`) replaces ``n_elements``.

    Raises
    ------
    TypeError
        For any other keyword, naming it and the allowed ones (these scenes take no controller,
        cache or integrator options).
    SpecError
        For a fidelity other than ``fem:N``, naming the key ``fidelity``.
    """
    if unknown:
        raise TypeError(
            f"run_scene() of a '{scene.kind}' scene got the option(s) "
            f"{', '.join(repr(k) for k in sorted(unknown))}; allowed: "
            f"{', '.join(repr(k) for k in RUN_OPTIONS)}"
        )
    scene = scene.with_fidelity(fidelity)
    if plots is not None:
        scene = dataclasses.replace(scene, plots=bool(plots))
    summary = _run(scene, None if out is None else Path(out))
    return FemSceneResult(scene=scene, summary=summary, files=[Path(p) for p in summary["files"]])
