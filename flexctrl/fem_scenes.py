"""Scenes for the finite-element models with moving supports: ``kind = "sliding_beam"``, ``"rp_arm"``, ``"telescoping"``.

``flexctrl simulate SCENE`` hands a scene whose ``kind`` is in :data:`FEM_SCENE_KINDS`
to :func:`run_fem_scene` (``--set`` overrides are applied to the raw document
first, so ``--set axial_shortening=false`` is validated like the file).

Keys (SI units; angles in degrees)::

    kind = "sliding_beam"           # or "rp_arm", "telescoping"
    name = "..."                    # default: the file's stem
    description = "..."
    C1 = 0.725                      # m, initial overhang W(0) beyond the outer support (Eq 57)
    C2 = 0.7                        # m, travel: W(T) = C1 - C2 (negative: extend)
    T = 3.5                         # s, duration of the motion
    tracked_end = "H"               # "H" | "E": end whose transverse displacement is reported
    driven_end = "H"                # "H" | "E": where the axial drive acts (default H; rp_arm: E)
    n_elements = 4                  # equal Hermite elements (a `fidelity = "fem:N"` key or
                                    # --fidelity fem:N overrides it; other fidelities are errors)
    dt = 1e-3                       # s, Newmark step
    duration = 3.5                  # s (default max(T, 1))
    gamma = 5.0                     # 1/s, Baumgarte (Eq 49)
    beta = 5.0                      # 1/s
    alpha = 0.25                    # Newmark (Eqs 50-51)
    delta = 0.5
    axial_shortening = true         # geometric stiffness of the rigid-body axial force (Eqs 16-18)
    max_violation = 1e-3            # m, bound on |Phi| (exceeding it stops the run)
    plots = true                    # write tip.png

``sliding_beam`` also takes the beam of Buffinton & Kane (defaults): ``L = 1.0`` (m),
``rho = 1.0`` (kg/m), ``EI = 1.0`` (N m^2), ``D = 0.25`` (m), ``tip_deflection = 0.01``
(m, initial static deflection of the tracked end).

``rp_arm`` adds ``model`` (``models/rp_arm.toml``), ``theta0`` and ``rotation``
(degrees: housing angle at t = 0 and its change over T), ``initial`` (``"rest"``, default,
or ``"static_load"`` with ``tip_deflection``), optional ``payload`` (kg) and
``gravity`` ([gx, gy] m/s^2) replacing the model file's, and an optional ``[drive]`` table::

    [drive]
    kind = "motion"                 # "motion": theta(t), W(t) by Eq 57 (default) | "force": full coupling
    coupling = "partial"            # motion only: "partial" (Eq 42, default) or "full" (Eq 43 with the
                                    # joint coordinates constrained: reports the torque and force needed)
    torque_amplitude = 2.0          # force only: N m, tau = A sin(2 pi t / T) on [0, T], then 0
    force_amplitude = 1.0           # force only: N, the axial drive at E, same shape

With ``kind = "force"`` the link starts undeformed at rest at ``W = C1``, ``theta = theta0``;
``C2`` and ``rotation`` do not apply (default 0; other values are errors), ``initial`` must be
``"rest"`` and ``driven_end`` ``"E"``.  Full coupling adds the columns ``torque, force``
(N m, N: applied, or needed by the motion).

``telescoping`` (two flexible links, Pan's Fig 5; :mod:`flexctrl.dynamics.fem.telescoping`)
takes ``model`` (``models/telescoping.toml``), ``theta0``, ``rotation``, optional ``payload``
and ``gravity``; ``W`` is the overhang of the inner tip beyond the outer link's mouth;
``n_elements`` applies to each link; ``driven_end`` must be ``"E"`` (the drive pushes the inner
root); appends the column ``outer_tip_y`` (m, the mouth's deflection).

Outputs in ``out_dir``: ``trajectory.csv`` with columns ``t, W, tip_y, phi_max,
phidot_max`` (s, m, m, m, m/s; ``rp_arm`` appends ``theta, tip_X, tip_Y``: rad and the
world position of H in m), ``summary.json`` (settings, wall time, wall time per
simulated second, peak ``|tip_y|``, maximal violations) and ``tip.png``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.errors import SpecError
from flexctrl.fidelity import Fidelity, parse_fidelity
from flexctrl.spec.reader import TableReader

FEM_SCENE_KINDS = ("sliding_beam", "rp_arm", "telescoping")
DRIVE_KINDS = ("motion", "force")
COUPLINGS = ("partial", "full")
ENDS = ("H", "E")
MAX_STEPS = 5_000_000


def _common(r: TableReader, kind: str, fidelity: Fidelity | None, force_drive: bool = False) -> dict[str, Any]:
    s: dict[str, Any] = {"kind": kind, "name": r.string("name", Path(r.source).stem),
                         "description": r.string("description", "")}
    s["C1"] = r.number("C1", unit="m")
    s["C2"] = r.number("C2", 0.0, unit="m") if force_drive else r.number("C2", unit="m")
    if force_drive and s["C2"] != 0.0:
        raise r.error("C2", f"value {s['C2']!r} does not apply to a force drive (W follows the force); allowed: 0 "
                            "or no key")
    s["T"] = r.positive("T", unit="s")
    s["tracked_end"] = r.string("tracked_end", "H", choices=ENDS)
    s["driven_end"] = r.string("driven_end", "H" if kind == "sliding_beam" else "E", choices=ENDS)
    s["n_elements"] = r.integer("n_elements", 4, low=1, high=256)
    # a `fidelity` key (as `flexctrl simulate --fidelity` writes into the document) or the argument
    for value, origin in ((r.raw("fidelity", None), r.source), (fidelity, "--fidelity")):
        if value is None:
            continue
        fid = parse_fidelity(value, source=origin, key="fidelity")
        if fid.kind != "fem":
            raise SpecError(f"value '{fid}' does not apply to '{kind}' scenes; allowed: 'fem:N' (N elements)",
                            source=origin, key="fidelity")
        s["n_elements"] = int(fid.count)
    s["dt"] = r.positive("dt", 1e-3, unit="s")
    s["duration"] = r.positive("duration", max(s["T"], 1.0), unit="s")
    if s["dt"] > s["duration"]:
        raise r.error("dt", f"value {s['dt']!r} is longer than the duration {s['duration']!r}; "
                            "allowed: 0 < dt <= duration")
    if s["duration"] / s["dt"] > MAX_STEPS:
        raise r.error("duration", f"value {s['duration']!r} needs {s['duration'] / s['dt']:.3g} steps of "
                                  f"{s['dt']!r} s; allowed: at most {MAX_STEPS:g} steps")
    s["gamma"] = r.positive("gamma", 5.0, unit="1/s")
    s["beta"] = r.positive("beta", 5.0, unit="1/s")
    s["alpha"] = r.positive("alpha", 0.25)
    s["delta"] = r.positive("delta", 0.5)
    s["axial_shortening"] = r.boolean("axial_shortening", True)
    s["max_violation"] = r.positive("max_violation", 1e-3, unit="m")
    s["plots"] = r.boolean("plots", True)
    return s


def read_fem_scene(document: dict[str, Any], source: str, fidelity: Fidelity | None = None) -> dict[str, Any]:
    """Validate a finite-element scene document into plain settings (see module docstring).

    Raises
    ------
    SpecError
        Naming the file, the key, the value and what is allowed.
    """
    r = TableReader(document, source)
    kind = r.string("kind", choices=FEM_SCENE_KINDS)
    drive = r.table_of("drive", {}) if kind == "rp_arm" else None
    drive_kind = drive.string("kind", "motion", choices=DRIVE_KINDS) if drive else "motion"
    s = _common(r, kind, fidelity, force_drive=drive_kind == "force")
    if kind == "telescoping" and s["driven_end"] != "E":
        raise r.error("driven_end", f"value {s['driven_end']!r} is not allowed for telescoping scenes; allowed: 'E' "
                                    "(the drive, anchored at the hub, pushes the inner link's root)")
    if kind == "sliding_beam":
        for key, default, unit in (("L", 1.0, "m"), ("rho", 1.0, "kg/m"), ("EI", 1.0, "N m^2"), ("D", 0.25, "m")):
            s[key] = r.positive(key, default, unit=unit)
        s["tip_deflection"] = r.number("tip_deflection", 0.01, unit="m")
        lo, hi = sorted((s["C1"], s["C1"] - s["C2"]))
        if not (lo >= 0.0 and hi <= s["L"] - s["D"]):
            raise r.error("C1", f"with C2 = {s['C2']!r} the overhang W runs over [{lo:g}, {hi:g}] m; allowed: "
                                f"within [0, L - D] = [0, {s['L'] - s['D']:g}] m (both supports on the beam)")
    else:
        from flexctrl.spec.scene import resolve_model_path

        base = Path(source).resolve().parent
        s["model"] = str(resolve_model_path(r.string("model", f"models/{kind}.toml"), base, r))
        s["theta0_deg"] = r.number("theta0", 0.0, unit="degrees")
        s["rotation_deg"] = r.number("rotation", 0.0, unit="degrees")
        s["payload"] = r.nonnegative("payload", unit="kg") if r.has("payload") else None
        s["gravity"] = list(r.numbers("gravity", length=2, unit="m/s^2")) if r.has("gravity") else None
        if kind == "rp_arm":
            s["initial"] = r.string("initial", "rest", choices=("rest", "static_load"))
            s["tip_deflection"] = r.number("tip_deflection", 0.01, unit="m")
            _read_drive(r, drive, drive_kind, s)
        else:
            _check_telescoping_stroke(r, s)
    r.finish()
    return s


def _read_drive(r: TableReader, drive: TableReader, kind: str, s: dict[str, Any]) -> None:
    s["drive"] = {"kind": kind}
    if kind == "motion":
        s["drive"]["coupling"] = drive.string("coupling", "partial", choices=COUPLINGS)
        if s["drive"]["coupling"] == "full" and (s["driven_end"] != "E" or s["initial"] != "rest"):
            raise drive.error("coupling", f"value 'full' needs driven_end = 'E' and initial = 'rest' (got "
                                          f"{s['driven_end']!r}, {s['initial']!r}); allowed: 'partial' otherwise")
    else:
        if s["rotation_deg"] != 0.0:
            raise r.error("rotation", f"value {s['rotation_deg']!r} does not apply to a force drive (theta follows "
                                      "the torque); allowed: 0 or no key")
        if s["initial"] != "rest":
            raise r.error("initial", f"value {s['initial']!r} is not available with a force drive; allowed: 'rest'")
        if s["driven_end"] != "E":
            raise r.error("driven_end", f"value {s['driven_end']!r} is not available with a force drive; allowed: "
                                        "'E' (the carriage)")
        s["drive"]["coupling"] = "full"
        s["drive"]["torque_amplitude"] = drive.number("torque_amplitude", 0.0, unit="N m")
        s["drive"]["force_amplitude"] = drive.number("force_amplitude", 0.0, unit="N")
    drive.finish()


def _check_telescoping_stroke(r: TableReader, s: dict[str, Any]) -> None:
    from flexctrl.dynamics.fem.telescoping import load_telescoping

    spec = load_telescoping(s["model"])
    shift = spec.outer.length - spec.inner.length
    try:
        spec.check_stroke([shift + s["C1"], shift + s["C1"] - s["C2"]])
    except SpecError as exc:
        message = str(exc).split("key 'C1': ", 1)[-1]
        raise r.error("C1", f"value {s['C1']!r} with C2 = {s['C2']!r}: {message}") from None


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
    settings = read_fem_scene(document, source, fidelity)
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


@dataclasses.dataclass(frozen=True)
class FemScene:
    """A validated finite-element scene for :data:`flexctrl.spec.scene.SCENE_KINDS` (``kind``, ``name``,
    the raw ``document`` and its ``source``)."""

    kind: str
    name: str
    document: dict
    source: str


@dataclasses.dataclass
class FemSceneResult:
    """What :func:`run_scene` produced: the scene, ``summary.json``'s content and the files written."""

    scene: FemScene
    summary: dict
    files: list[Path]


def read_scene(document: dict[str, Any], source: str, base_dir: Path | None = None) -> FemScene:
    """Reader with the ``SCENE_KINDS`` signature: validates now, so errors surface at load time."""
    settings = read_fem_scene(document, source)
    return FemScene(kind=settings["kind"], name=settings["name"], document=document, source=source)


def run_scene(scene: FemScene, out: str | Path | None = None, *, plots: bool | None = None,
              fidelity: Fidelity | str | None = None, **_ignored: Any) -> FemSceneResult:
    """Runner with the ``SCENE_KINDS`` signature, e.g.
    ``register_scene_kind("sliding_beam", "flexctrl.fem_scenes:read_scene", "flexctrl.fem_scenes:run_scene")``."""
    document = dict(scene.document)
    if plots is not None:
        document["plots"] = bool(plots)
    summary = run_fem_scene(document, scene.source, None if out is None else Path(out), fidelity)
    return FemSceneResult(scene=scene, summary=summary, files=[Path(p) for p in summary["files"]])
