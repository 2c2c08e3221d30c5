"""Closed-loop scenes (``kind = "closed_loop"``): a plant scene plus a target and a controller.

Everything of a ``kind = "arm"`` scene (model, payload, fidelity, modes, gravity,
integrator, dt, duration, ``[initial]``, ``[damping]``) describes the *plant*,
integrated at ``dt`` (s); the controller runs at its own sample time with a
zero-order hold.  The extra keys::

    kind = "closed_loop"
    controller = "controllers/lqr.toml"  # default controller file (CLI --controller overrides)
    design_payload = 2.0                 # kg the controller is designed for (default: payload)
    controller_fidelity = "amm:2"        # model the controller is designed on (default: fidelity)
    design_configuration = [0, 90, 0]    # degrees: the joint angles the controller is designed
                                         # (linearised) at (default: the target)
    [target]   q = [30, 0, 0]            # degrees: the joint angles to move to
               # or move = [30, 0, 0]    # degrees relative to the initial joint angles (for sweeps)
               profile = "quintic"       # "step" (default: the reference jumps at t = 0), "quintic"
               move_time = 1.5           # s, duration of the quintic (required with it)
               deflection = "quasi_static"   # elastic reference of LQR/MPC/NMPC: "quasi_static"
                                             # or "static"
    [return]   t_start = 4.0             # s: move back to the initial joint angles from then on
                                         # (same profile and move time); the run is judged there
    [[payload_changes]]                  # the plant's payload steps at rest (a grasp, a release)
               time = 3.0                # s
               mass = 4.0                # kg, from then on
    [noise]    enabled = true, seed = 0  # measurement noise as set in the controller's sensors
    [metrics]  settle_allowance = 2.0 (s), band = 1e-3 (m)
               divergence_deflection = 0.1   # a link tip deflection beyond this fraction of the
                                             # link's length means the closed loop diverged
                                             # (default: the larger of 0.1 of the length and 4x
                                             # the static deflection of the joint's torque limit)
               divergence_angle = 90.0       # deg: so does a joint this far outside its move
               stable_band = 0.01            # m: settled_within_band = 1 needs the tip error of
                                             # the run's last second below it

Angles are in degrees in the file and radians in the dataclass.  The reference
(:mod:`flexctrl.control.reference_trajectory`) goes from the initial joint angles to the target;
every controller reads it at its sample times.  The residual-vibration window of
:mod:`flexctrl.loop.metrics` starts ``settle_allowance`` after the reference arrives (at
t = 0 for the step, at ``move_time`` for the quintic).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flexctrl.errors import SpecError, keywords_checked
from flexctrl.spec import shipped
from flexctrl.spec.arm_scene import ArmScene, read_arm_scene
from flexctrl.spec.fidelity import Fidelity, parse_fidelity
from flexctrl.spec.reader import TableReader
from flexctrl.spec.reference import DEFLECTIONS, PROFILES, JointReference, JointSequence


@keywords_checked
@dataclass(frozen=True)
class MetricSettings:
    """How a closed-loop run is judged: a scene's ``[metrics]`` table (the defaults are the file's).

    Attributes
    ----------
    settle_allowance : float
        s after the reference arrives before the residual-vibration window opens.
    band : float
        m: the settling band of the tip error.
    divergence_deflection : float or None
        A link tip deflection beyond this fraction of the link's length means divergence.
        None (the default): the larger of 0.1 of the length and 4 times the tip deflection
        ``tau L^2 / (2 EI)`` the joint's torque limit ``tau`` holds statically
        (:func:`flexctrl.loop.monitors.deflection_bounds`), so a light arm's ordinary moves
        stay inside while a stiff arm's bound stays 0.1 of its length.
    divergence_angle : float
        rad: so does a joint this far outside the range of its move.
    stable_band : float
        m: ``stable = 1`` needs the tip error of the run's last second below it.
    """

    settle_allowance: float = 2.0
    band: float = 1e-3
    divergence_deflection: float | None = None
    divergence_angle: float = math.pi / 2
    stable_band: float = 0.01


_EXTRA_KEYS = (
    "controller",
    "design_payload",
    "controller_fidelity",
    "design_configuration",
    "target",
    "noise",
    "metrics",
    "return",
    "payload_changes",
)


@dataclass(frozen=True)
class ClosedLoopScene:
    """A validated closed-loop scene; ``plant`` holds the plant part (an :class:`ArmScene`)."""

    plant: ArmScene
    target_q: tuple[float, ...]
    controller: Path | None
    design_payload: float | None
    controller_fidelity: Fidelity | None
    noise: bool
    seed: int
    settle_allowance: float
    band: float
    profile: str = "step"
    move_time: float = 0.0
    deflection: str = "quasi_static"
    design_q: tuple[float, ...] | None = None
    divergence_deflection: float | None = None
    divergence_angle: float = math.pi / 2
    stable_band: float = 0.01
    kind: str = "closed_loop"
    return_at: float | None = None
    payload_changes: tuple[tuple[float, float], ...] = ()

    @property
    def name(self) -> str:
        return self.plant.name

    @property
    def source(self) -> str:
        return self.plant.source

    @property
    def start_q(self) -> tuple[float, ...]:
        """Joint angles (rad) the reference starts from: the initial ones (zero when not given)."""
        return self.plant.q0 if self.plant.q0 is not None else (0.0,) * len(self.target_q)

    @property
    def design_configuration(self) -> tuple[float, ...]:
        """Joint angles (rad) the controller is designed at (default: the target)."""
        return self.design_q if self.design_q is not None else self.target_q

    def joint_reference(self):
        """The :class:`~flexctrl.spec.reference.JointReference` from the start to the target.

        With a ``[return]`` table, a :class:`~flexctrl.spec.reference.JointSequence` that moves
        back to the start at ``return_at``.
        """
        out = JointReference(self.start_q, self.target_q, self.profile, self.move_time)
        if self.return_at is None:
            return out
        back = JointReference(
            self.target_q, self.start_q, self.profile, self.move_time, self.return_at
        )
        return JointSequence((out, back))

    @property
    def final_q(self) -> tuple[float, ...]:
        """Joint angles (rad) the run ends at: the target, or the start after a return move."""
        return self.target_q if self.return_at is None else self.start_q

    @property
    def t_arrive(self) -> float:
        """Time (s) the reference arrives for good: 0 for a step, ``move_time`` for a quintic
        (after the return move with a ``[return]`` table)."""
        return self.joint_reference().t_arrive

    @property
    def metric_settings(self) -> MetricSettings:
        """How a run of the scene is judged (its ``[metrics]`` table)."""
        return MetricSettings(
            settle_allowance=self.settle_allowance,
            band=self.band,
            divergence_deflection=self.divergence_deflection,
            divergence_angle=self.divergence_angle,
            stable_band=self.stable_band,
        )

    def settings(self) -> dict[str, Any]:
        """Plain JSON-ready data (angles in degrees)."""
        return {
            **self.plant.settings(),
            "kind": self.kind,
            "target_q_deg": [math.degrees(a) for a in self.target_q],
            "profile": self.profile,
            "move_time_s": self.move_time,
            "deflection_reference": self.deflection,
            "design_configuration_deg": [math.degrees(a) for a in self.design_configuration],
            "controller": str(self.controller) if self.controller else None,
            "design_payload_kg": self.design_payload,
            "return_at_s": self.return_at,
            "payload_changes": [{"time_s": t, "mass_kg": m} for t, m in self.payload_changes],
            "controller_fidelity": str(self.controller_fidelity)
            if self.controller_fidelity
            else None,
            "noise": self.noise,
            "seed": self.seed,
            "settle_allowance_s": self.settle_allowance,
            "band_m": self.band,
            "divergence_deflection": self.divergence_deflection,
            "divergence_angle_deg": math.degrees(self.divergence_angle),
            "stable_band_m": self.stable_band,
        }


def read_closed_loop_scene(
    document: dict[str, Any], source: str, base_dir: Path
) -> ClosedLoopScene:
    """Validate a ``kind = "closed_loop"`` document (see module docstring)."""
    plant = read_arm_scene(document, source, base_dir, kind="closed_loop", accept=_EXTRA_KEYS)
    if plant.integrator != "rk4":
        raise SpecError(
            f"value {plant.integrator!r} is not allowed in a closed-loop scene: the plant steps "
            "between the controller's samples with the compiled fixed-step RK4 at dt; allowed: "
            "'rk4' (other integrators: an open-loop scene, kind = \"arm\")",
            source=source,
            key="integrator",
        )
    r = TableReader({k: document[k] for k in _EXTRA_KEYS if k in document}, source)
    controller = _read_controller(r, base_dir)
    design_payload = r.nonnegative("design_payload", unit="kg") if r.has("design_payload") else None
    cf = (
        parse_fidelity(r.raw("controller_fidelity"), source=source, key="controller_fidelity")
        if r.has("controller_fidelity")
        else None
    )
    target = _read_target(r.table_of("target"), plant)
    design_q = _read_design_configuration(r, len(target.q))
    noise = r.table_of("noise", {})
    enabled, seed = noise.boolean("enabled", False), noise.integer("seed", 0, low=0)
    noise.finish()
    judge = _read_metrics(r.table_of("metrics", {}))
    move_time = target.move_time if target.profile == "quintic" else 0.0
    return_at = _read_return(r, move_time)
    changes = _read_payload_changes(r, plant.duration)
    r.finish()
    t_arrive = move_time if return_at is None else return_at + move_time
    if t_arrive + judge.settle_allowance >= plant.duration:
        raise r.error(
            "metrics.settle_allowance",
            f"value {judge.settle_allowance!r} leaves no residual window after the move "
            f"(arrives at {t_arrive:g} s); allowed: < duration - arrival "
            f"({plant.duration - t_arrive:g} s)",
        )
    return ClosedLoopScene(
        plant,
        target.q,
        controller,
        design_payload,
        cf,
        enabled,
        seed,
        judge.settle_allowance,
        judge.band,
        target.profile,
        move_time,
        target.deflection,
        design_q,
        judge.divergence_deflection,
        judge.divergence_angle,
        judge.stable_band,
        return_at=return_at,
        payload_changes=changes,
    )


def _read_return(r: TableReader, move_time: float) -> float | None:
    """``[return]``: ``t_start`` (s) of the move back to the start, or None."""
    if not r.has("return"):
        return None
    table = r.table_of("return")
    t_start = table.number(
        "t_start", low=move_time, unit=f"s, at or after the arrival {move_time:g}"
    )
    table.finish()
    return t_start


def _read_payload_changes(r: TableReader, duration: float) -> tuple[tuple[float, float], ...]:
    """``[[payload_changes]]``: ``(time s, mass kg)`` by time, or none."""
    if not r.has("payload_changes"):
        return ()
    changes = []
    for table in r.tables("payload_changes", min_count=1):
        when = table.number("time", low=0.0, high=duration, unit="s, within the run")
        changes.append((when, table.nonnegative("mass", unit="kg")))
        table.finish()
    return tuple(sorted(changes))


def _read_controller(r: TableReader, base_dir: Path) -> Path | None:
    """``controller``: a file relative to the scene's folder, or a shipped controller's name."""
    if not r.has("controller"):
        return None
    name = r.string("controller")
    try:
        return shipped.find(name, "controller", base_dir)
    except SpecError as exc:
        raise r.error("controller", f"file {name!r} not found ({exc.message})") from None


@dataclass(frozen=True)
class _Target:
    """The ``[target]`` table read: joint angles (rad) and the reference to them."""

    q: tuple[float, ...]
    profile: str
    move_time: float
    deflection: str


def _read_target(target: TableReader, plant: ArmScene) -> _Target:
    """``[target]``: ``q`` (absolute) or ``move`` (relative), degrees; the reference's shape."""
    if target.has("q") == target.has("move"):
        given = "both are given" if target.has("q") else "missing required key"
        raise target.error(
            "q",
            f"{given}; allowed: exactly one of 'target.q' (absolute) and 'target.move' (relative "
            "to initial.q), degrees",
        )
    if target.has("q"):
        target_q = tuple(math.radians(a) for a in target.degrees("q"))
    else:
        move = target.degrees("move")
        start = plant.q0 if plant.q0 is not None else (0.0,) * len(move)
        if len(move) != len(start):
            raise target.error(
                "move",
                f"has {len(move)} values for {len(start)} initial joint angles; allowed: one per "
                "joint",
            )
        target_q = tuple(a + math.radians(b) for a, b in zip(start, move))
    profile = target.string("profile", "step", choices=PROFILES)
    if profile == "quintic":
        if not target.has("move_time"):
            raise target.error(
                "move_time",
                'is missing; allowed: a move time > 0 s, required with profile = "quintic"',
            )
        move_time = target.positive("move_time", unit="s")
    else:  # a step has no duration; a move_time is accepted (and unused) so a study can switch
        move_time = target.positive("move_time", unit="s") if target.has("move_time") else 0.0
    deflection = target.string("deflection", "quasi_static", choices=DEFLECTIONS)
    target.finish()
    return _Target(target_q, profile, move_time, deflection)


def _read_design_configuration(r: TableReader, n_joints: int) -> tuple[float, ...] | None:
    """``design_configuration`` (degrees, one per joint), or None: the target."""
    if not r.has("design_configuration"):
        return None
    values = r.degrees("design_configuration")
    if len(values) != n_joints:
        raise r.error(
            "design_configuration",
            f"has {len(values)} values for {n_joints} joints; "
            "allowed: one angle per joint (degrees)",
        )
    return tuple(math.radians(a) for a in values)


def _read_metrics(metrics: TableReader) -> MetricSettings:
    """``[metrics]``: how a run is judged (the defaults are :class:`MetricSettings`')."""
    default = MetricSettings()
    settle = metrics.nonnegative("settle_allowance", default.settle_allowance, unit="s")
    band = metrics.positive("band", default.band, unit="m")
    div_deflection = (
        metrics.positive("divergence_deflection")
        if metrics.has("divergence_deflection")
        else default.divergence_deflection
    )
    div_angle = math.radians(
        metrics.positive("divergence_angle", math.degrees(default.divergence_angle), unit="degrees")
    )
    stable_band = metrics.positive("stable_band", default.stable_band, unit="m")
    metrics.finish()
    return MetricSettings(settle, band, div_deflection, div_angle, stable_band)
