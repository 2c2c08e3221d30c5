"""Running the finite-element scenes (``kind = "sliding_beam"``, ``"rp_arm"``, ``"telescoping"``).

The keys are described in :mod:`flexctrl.spec.fem_scene`.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.spec.fem_scene import FemScene, fem_settings
from flexctrl.spec.fidelity import Fidelity


def _simulate(s: dict[str, Any]):
    """Run the validated scene; returns (result, extra columns, model facts)."""
    common = dict(gamma=s["gamma"], beta=s["beta"], alpha=s["alpha"], delta=s["delta"],
                  axial_shortening=s["axial_shortening"], max_violation=s["max_violation"])
    if s["kind"] == "sliding_beam":
        from flexctrl.dynamics.fem.sliding_beam import SlidingBeamCase, simulate_sliding_beam

        case = SlidingBeamCase(s["name"], C1=s["C1"], C2=s["C2"], T=s["T"], tracked_end=s["tracked_end"],
                               driven_end=s["driven_end"], L=s["L"], rho=s["rho"], EI=s["EI"], D=s["D"],
                               tip_deflection=s["tip_deflection"])
        res = simulate_sliding_beam(case, s["n_elements"], dt=s["dt"], duration=s["duration"], **common)
        return res, {}, {"ndof": int(res.q.shape[1])}
    from flexctrl.dynamics.fem.rp_arm import (RPForces, RPMotion, load_rp_arm, simulate_rp_arm,
                                              simulate_rp_arm_full)

    if s["kind"] == "telescoping":
        return _simulate_telescoping(s, common)
    spec = load_rp_arm(s["model"])
    if s["payload"] is not None:
        spec = dataclasses.replace(spec, payload_mass=s["payload"])
    if s["gravity"] is not None:
        spec = dataclasses.replace(spec, gravity=tuple(s["gravity"]))
    motion = RPMotion(C1=s["C1"], C2=s["C2"], T=s["T"], theta0=math.radians(s["theta0_deg"]),
                      dtheta=math.radians(s["rotation_deg"]))
    drive = s["drive"]
    if drive["coupling"] == "partial":
        res = simulate_rp_arm(spec, motion, s["n_elements"], dt=s["dt"], duration=s["duration"],
                              driven_end=s["driven_end"], tracked_end=s["tracked_end"], initial=s["initial"],
                              tip_deflection=s["tip_deflection"], **common)
    else:
        if drive["kind"] == "force":
            motion = RPForces.sine(drive["torque_amplitude"], drive["force_amplitude"], s["T"],
                                   theta0=math.radians(s["theta0_deg"]), W0=s["C1"])
        res = simulate_rp_arm_full(spec, motion, s["n_elements"], dt=s["dt"], duration=s["duration"],
                                   tracked_end=s["tracked_end"], **common)
    extra = {"theta": res.theta, "tip_X": res.tip_world[:, 0], "tip_Y": res.tip_world[:, 1]}
    if drive["coupling"] == "full":
        extra.update(torque=res.torque, force=res.force)
    facts = {"ndof": int(res.q.shape[1]), "support_inner_m": spec.support_inner, "support_outer_m": spec.support_outer,
             "link": {"length_m": spec.length, "mass_per_length_kg_m": spec.mass_per_length, "EI_N_m2": spec.EI},
             "payload_kg": spec.payload_mass, "gravity_m_s2": list(spec.gravity)}
    return res, extra, facts


def _simulate_telescoping(s: dict[str, Any], common: dict[str, Any]):
    from flexctrl.dynamics.fem.rp_arm import RPMotion
    from flexctrl.dynamics.fem.telescoping import load_telescoping, simulate_telescoping

    spec = load_telescoping(s["model"])
    if s["payload"] is not None:
        spec = dataclasses.replace(spec, payload_mass=s["payload"])
    if s["gravity"] is not None:
        spec = dataclasses.replace(spec, gravity=tuple(s["gravity"]))
    motion = RPMotion(C1=s["C1"], C2=s["C2"], T=s["T"], theta0=math.radians(s["theta0_deg"]),
                      dtheta=math.radians(s["rotation_deg"]))
    res = simulate_telescoping(spec, motion, s["n_elements"], s["n_elements"], dt=s["dt"], duration=s["duration"],
                               tracked_end=s["tracked_end"], **common)
    extra = {"theta": res.theta, "tip_X": res.tip_world[:, 0], "tip_Y": res.tip_world[:, 1],
             "outer_tip_y": res.outer_tip_y}
    facts = {"ndof": int(res.q.shape[1]), "hub_radius_m": spec.hub_radius,
             "outer": dataclasses.asdict(spec.outer), "inner": dataclasses.asdict(spec.inner),
             "contacts": [dataclasses.asdict(c) for c in spec.contacts], "payload_kg": spec.payload_mass,
             "gravity_m_s2": list(spec.gravity)}
    return res, extra, facts


def _plot(path: Path, res, s: dict[str, Any], extra: dict[str, np.ndarray]) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 5.5), layout="constrained")
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    ax1.plot(res.t, 1e3 * res.tip_y)
    ax1.set_ylabel(f"tip_y at {s['tracked_end']} (mm)")
    ax1.set_title(f"{s['name']}: {s['kind']}, {s['n_elements']} elements, dt = {s['dt']:g} s, "
                  f"axial shortening {'on' if s['axial_shortening'] else 'off'}", fontsize=9)
    if "outer_tip_y" in extra:
        ax1.plot(res.t, 1e3 * extra["outer_tip_y"], label="outer link mouth")
        ax1.lines[0].set_label(f"inner link {s['tracked_end']}")
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


def run_fem_scene(document: dict, source: str, out_dir: Path | None, fidelity: Fidelity | None = None) -> dict:
    """Validate, simulate and (with ``out_dir``) write a finite-element scene.

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
    settings = fem_settings(document, source, fidelity)
    start = time.perf_counter()
    res, extra, facts = _simulate(settings)
    wall = time.perf_counter() - start
    simulated = float(res.t[-1] - res.t[0])
    summary: dict[str, Any] = {
        "scene": {k: v for k, v in settings.items()},
        "source": source,
        "kind": settings["kind"],
        "integrator": "newmark + baumgarte (flexctrl.sim.newmark_dae)",
        "n_elements": settings["n_elements"],
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
        columns = {"t": res.t, "W": res.W, "tip_y": res.tip_y, "phi_max": res.phi_violation,
                   "phidot_max": res.phidot_violation, **extra}
        data = np.column_stack(list(columns.values()))
        csv = out / "trajectory.csv"
        np.savetxt(csv, data, delimiter=",", header=",".join(columns), comments="", fmt="%.12g")
        files = [csv]
        if settings["plots"]:
            png = out / "tip.png"
            _plot(png, res, settings, extra)
            files.append(png)
        summary["files"] = [str(p) for p in files] + [str(out / "summary.json")]
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary


@dataclasses.dataclass
class FemSceneResult:
    """What :func:`run_scene` produced: the scene, ``summary.json``'s content and the files written."""

    scene: FemScene
    summary: dict
    files: list[Path]


def run_scene(scene: FemScene, out: str | Path | None = None, *, plots: bool | None = None,
              fidelity: Fidelity | str | None = None, **_ignored: Any) -> FemSceneResult:
    """Runner with the ``SCENE_KINDS`` signature, e.g.
    ``flexctrl.scenes.SCENE_RUNNERS``."""
    document = dict(scene.document)
    if plots is not None:
        document["plots"] = bool(plots)
    summary = run_fem_scene(document, scene.source, None if out is None else Path(out), fidelity)
    return FemSceneResult(scene=scene, summary=summary, files=[Path(p) for p in summary["files"]])
