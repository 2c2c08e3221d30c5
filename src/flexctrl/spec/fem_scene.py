"""Finite-element scenes with moving supports: ``sliding_beam``, ``rp_arm``, ``telescoping``.

:func:`read_fem_scene` (the reader :func:`flexctrl.spec.scene.load_scene` uses for every
``kind`` in :data:`FEM_SCENE_KINDS`) validates a scene once, into a frozen description
(:mod:`flexctrl.spec.fem_scene_types`, re-exported here): :class:`SlidingBeamScene`,
:class:`RPArmScene` or :class:`TelescopingScene`, all :class:`FemScene`;
:meth:`FemScene.settings` gives them back as the plain data ``summary.json`` records under
``"scene"``.  ``--set`` overrides are applied to the raw document first, so ``--set
axial_shortening=false`` is validated like the file.  Running is
:func:`flexctrl.scenes.run_fem_scene.run_scene`.

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
    kind = "motion"                 # "motion": theta(t), W(t) by Eq 57 (default) | "force": full
                                    # coupling
    coupling = "partial"            # motion only: "partial" (Eq 42, default) or "full" (Eq 43
                                    # with the joint coordinates constrained: reports the torque
                                    # and force needed)
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
from pathlib import Path
from typing import Any

from flexctrl.errors import SpecError
from flexctrl.spec.arm_scene import resolve_model_path
from flexctrl.spec.fem_models import RPArmSpec, TelescopingSpec, load_rp_arm, load_telescoping
from flexctrl.spec.fem_scene_types import (
    COUPLINGS,
    DRIVE_KINDS,
    ENDS,
    FEM_SCENE_KINDS,
    MAX_STEPS,
    SCENE_CLASSES,
    AnyFemScene,
    FemScene,
    RPArmScene,
    RPDrive,
    SlidingBeamScene,
    TelescopingScene,
    fem_elements,
)
from flexctrl.spec.reader import TableReader

__all__ = [
    "COUPLINGS",
    "DRIVE_KINDS",
    "ENDS",
    "FEM_SCENE_KINDS",
    "MAX_STEPS",
    "SCENE_CLASSES",
    "AnyFemScene",
    "FemScene",
    "RPArmScene",
    "RPDrive",
    "SlidingBeamScene",
    "TelescopingScene",
    "read_fem_scene",
]


def _common(r: TableReader, kind: str, force_drive: bool = False) -> dict[str, Any]:
    s: dict[str, Any] = {
        "name": r.string("name", Path(r.source).stem),
        "description": r.string("description", ""),
    }
    s["C1"] = r.number("C1", unit="m")
    s["C2"] = r.number("C2", 0.0, unit="m") if force_drive else r.number("C2", unit="m")
    if force_drive and s["C2"] != 0.0:
        raise r.error(
            "C2",
            f"value {s['C2']!r} does not apply to a force drive (W follows the force); allowed: 0 "
            "or no key",
        )
    s["T"] = r.positive("T", unit="s")
    s["tracked_end"] = r.string("tracked_end", "H", choices=ENDS)
    s["driven_end"] = r.string("driven_end", "H" if kind == "sliding_beam" else "E", choices=ENDS)
    s["n_elements"] = r.integer("n_elements", 4, low=1, high=256)
    fidelity = r.raw(
        "fidelity", None
    )  # as `flexctrl simulate --fidelity` writes it into the document
    if fidelity is not None:
        s["n_elements"] = fem_elements(fidelity, kind, r.source)
    s["dt"] = r.positive("dt", 1e-3, unit="s")
    s["duration"] = r.positive("duration", max(s["T"], 1.0), unit="s")
    if s["dt"] > s["duration"]:
        raise r.error(
            "dt",
            f"value {s['dt']!r} is longer than the duration {s['duration']!r}; "
            "allowed: 0 < dt <= duration",
        )
    if s["duration"] / s["dt"] > MAX_STEPS:
        raise r.error(
            "duration",
            f"value {s['duration']!r} needs {s['duration'] / s['dt']:.3g} steps of "
            f"{s['dt']!r} s; allowed: at most {MAX_STEPS:g} steps",
        )
    s["gamma"] = r.positive("gamma", 5.0, unit="1/s")
    s["beta"] = r.positive("beta", 5.0, unit="1/s")
    s["alpha"] = r.positive("alpha", 0.25)
    s["delta"] = r.positive("delta", 0.5)
    s["axial_shortening"] = r.boolean("axial_shortening", True)
    s["max_violation"] = r.positive("max_violation", 1e-3, unit="m")
    s["plots"] = r.boolean("plots", True)
    return s


def read_fem_scene(
    document: dict[str, Any], source: str, base_dir: Path | None = None
) -> AnyFemScene:
    """Validate a finite-element scene document (see the module docstring) into its description.

    The reader of :data:`flexctrl.spec.scene.SCENE_READERS` for every kind of
    :data:`FEM_SCENE_KINDS`: everything is checked here, once, including the model file and
    (``telescoping``) the contacts over the stroke, so errors surface when the scene is loaded.

    Parameters
    ----------
    document
        The parsed scene (``--set`` overrides already applied).
    source
        Its file name, for error messages; a relative ``model`` is looked up next to it first,
        then in the working directory and the repository.
    base_dir
        Accepted for the common reader signature; not used (the model is found from ``source``).

    Raises
    ------
    SpecError
        Naming the file, the key, the value and what is allowed.
    """
    r = TableReader(document, source)
    kind = r.string("kind", choices=FEM_SCENE_KINDS)
    drive = r.table_of("drive", {}) if kind == "rp_arm" else None
    drive_kind = drive.string("kind", "motion", choices=DRIVE_KINDS) if drive else "motion"
    s = _common(r, kind, force_drive=drive_kind == "force")
    if kind == "telescoping" and s["driven_end"] != "E":
        raise r.error(
            "driven_end",
            f"value {s['driven_end']!r} is not allowed for telescoping scenes; allowed: 'E' "
            "(the drive, anchored at the hub, pushes the inner link's root)",
        )
    if kind == "sliding_beam":
        for key, default, unit in (
            ("L", 1.0, "m"),
            ("rho", 1.0, "kg/m"),
            ("EI", 1.0, "N m^2"),
            ("D", 0.25, "m"),
        ):
            s[key] = r.positive(key, default, unit=unit)
        s["tip_deflection"] = r.number("tip_deflection", 0.01, unit="m")
        lo, hi = sorted((s["C1"], s["C1"] - s["C2"]))
        if not (lo >= 0.0 and hi <= s["L"] - s["D"]):
            raise r.error(
                "C1",
                f"with C2 = {s['C2']!r} the overhang W runs over [{lo:g}, {hi:g}] m; allowed: "
                f"within [0, L - D] = [0, {s['L'] - s['D']:g}] m (both supports on the beam)",
            )
        r.finish()
        return SlidingBeamScene(**s, source=source)
    base = Path(source).resolve().parent
    s["model"] = str(resolve_model_path(r.string("model", f"models/{kind}.toml"), base, r))
    s["theta0_deg"] = r.degree("theta0", 0.0)
    s["rotation_deg"] = r.degree("rotation", 0.0)
    s["payload"] = r.nonnegative("payload", unit="kg") if r.has("payload") else None
    s["gravity"] = tuple(r.numbers("gravity", length=2, unit="m/s^2")) if r.has("gravity") else None
    if kind == "rp_arm":
        s["initial"] = r.string("initial", "rest", choices=("rest", "static_load"))
        s["tip_deflection"] = r.number("tip_deflection", 0.01, unit="m")
        assert drive is not None  # read above for rp_arm scenes
        s["drive"] = _read_drive(r, drive, drive_kind, s)
        spec = load_rp_arm(s["model"])
        if spec.joint == "clamped" and s["driven_end"] != "E":
            raise r.error(
                "driven_end",
                f"value {s['driven_end']!r} is not allowed with the model's joint = 'clamped' "
                f"({s['model']}); allowed: 'E' (the link is clamped in the carriage)",
            )
        r.finish()
        return RPArmScene(**s, model_spec=_with_overrides(spec, s), source=source)
    telescoping = _check_telescoping_stroke(r, s)
    r.finish()
    return TelescopingScene(**s, model_spec=_with_overrides(telescoping, s), source=source)


def _read_drive(r: TableReader, drive: TableReader, kind: str, s: dict[str, Any]) -> RPDrive:
    if kind == "motion":
        coupling = drive.choice("coupling", COUPLINGS, "partial")
        if coupling == "full" and (s["driven_end"] != "E" or s["initial"] != "rest"):
            raise drive.error(
                "coupling",
                f"value 'full' needs driven_end = 'E' and initial = 'rest' (got "
                f"{s['driven_end']!r}, {s['initial']!r}); allowed: 'partial' otherwise",
            )
        out = RPDrive("motion", coupling)
    else:
        if s["rotation_deg"] != 0.0:
            raise r.error(
                "rotation",
                f"value {s['rotation_deg']!r} does not apply to a force drive (theta follows "
                "the torque); allowed: 0 or no key",
            )
        if s["initial"] != "rest":
            raise r.error(
                "initial",
                f"value {s['initial']!r} is not available with a force drive; allowed: 'rest'",
            )
        if s["driven_end"] != "E":
            raise r.error(
                "driven_end",
                f"value {s['driven_end']!r} is not available with a force drive; allowed: "
                "'E' (the carriage)",
            )
        out = RPDrive(
            "force",
            "full",
            torque_amplitude=drive.number("torque_amplitude", 0.0, unit="N m"),
            force_amplitude=drive.number("force_amplitude", 0.0, unit="N"),
        )
    drive.finish()
    return out


def _check_telescoping_stroke(r: TableReader, s: dict[str, Any]) -> TelescopingSpec:
    spec = load_telescoping(s["model"])
    shift = spec.outer.length - spec.inner.length
    try:
        spec.check_stroke([shift + s["C1"], shift + s["C1"] - s["C2"]])
    except SpecError as exc:
        message = str(exc).split("key 'C1': ", 1)[-1]
        raise r.error("C1", f"value {s['C1']!r} with C2 = {s['C2']!r}: {message}") from None
    return spec


def _with_overrides(spec: RPArmSpec | TelescopingSpec, s: dict[str, Any]) -> Any:
    """The model file's description with the scene's ``payload`` and ``gravity`` (when given)."""
    if s["payload"] is not None:
        spec = dataclasses.replace(spec, payload_mass=s["payload"])
    if s["gravity"] is not None:
        spec = dataclasses.replace(spec, gravity=tuple(s["gravity"]))
    return spec
