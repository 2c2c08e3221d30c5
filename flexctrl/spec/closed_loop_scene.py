"""Closed-loop scenes (``kind = "closed_loop"``): a plant scene plus a target and a controller.

Everything of a ``kind = "arm"`` scene (model, payload, fidelity, modes, gravity,
integrator, dt, duration, ``[initial]``, ``[damping]``) describes the *plant*,
integrated at ``dt`` (s); the controller runs at its own sample time with a
zero-order hold.  The extra keys::

    kind = "closed_loop"
    controller = "controllers/lqr.toml"  # default controller file (CLI --controller overrides)
    design_payload = 2.0                 # kg the controller is designed for (mismatch; default: payload)
    controller_fidelity = "amm:2"        # model the controller is designed on (default: fidelity)
    [target]   q = [30, 0, 0]            # degrees: the joint angles to move to (a step reference at t = 0)
               # or move = [30, 0, 0]    # degrees relative to the initial joint angles (for sweeps)
    [noise]    enabled = true, seed = 0  # measurement noise as set in the controller's sensors
    [metrics]  settle_allowance = 2.0 (s), band = 1e-3 (m)

Angles are in degrees in the file and radians in the dataclass.  The residual-
vibration window of :mod:`flexctrl.metrics` starts ``settle_allowance`` after the
reference arrives (at t = 0 for the step reference).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flexctrl.fidelity import Fidelity, parse_fidelity
from flexctrl.spec.reader import TableReader
from flexctrl.spec.scene import ArmScene, read_arm_scene

_EXTRA_KEYS = ("controller", "design_payload", "controller_fidelity", "target", "noise", "metrics")


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
    kind: str = "closed_loop"

    @property
    def name(self) -> str:
        return self.plant.name

    @property
    def source(self) -> str:
        return self.plant.source

    def settings(self) -> dict[str, Any]:
        """Plain JSON-ready data (angles in degrees)."""
        return {
            **self.plant.settings(),
            "kind": self.kind,
            "target_q_deg": [math.degrees(a) for a in self.target_q],
            "controller": str(self.controller) if self.controller else None,
            "design_payload_kg": self.design_payload,
            "controller_fidelity": str(self.controller_fidelity) if self.controller_fidelity else None,
            "noise": self.noise,
            "seed": self.seed,
            "settle_allowance_s": self.settle_allowance,
            "band_m": self.band,
        }


def read_closed_loop_scene(document: dict[str, Any], source: str, base_dir: Path) -> ClosedLoopScene:
    """Validate a ``kind = "closed_loop"`` document (see module docstring)."""
    plant_doc = {k: copy.deepcopy(v) for k, v in document.items() if k not in _EXTRA_KEYS}
    plant_doc["kind"] = "arm"
    plant = read_arm_scene(plant_doc, source, base_dir)
    plant = ArmScene(**{**plant.__dict__, "kind": "arm"})
    r = TableReader({k: document[k] for k in _EXTRA_KEYS if k in document}, source)
    controller = None
    if r.has("controller"):
        name = r.string("controller")
        candidates = [base_dir / name, Path.cwd() / name, Path(__file__).resolve().parents[2] / name]
        found = next((c for c in candidates if c.is_file()), None)
        if found is None:
            raise r.error("controller", f"file '{name}' not found (looked relative to the scene, the working folder and the repository)")
        controller = found
    design_payload = r.nonnegative("design_payload", unit="kg") if r.has("design_payload") else None
    cf = parse_fidelity(r.raw("controller_fidelity"), source=source, key="controller_fidelity") if r.has("controller_fidelity") else None
    target = r.table_of("target")
    if target.has("q") == target.has("move"):
        raise target.error("q", "give exactly one of 'target.q' (absolute) and 'target.move' (relative to initial.q), degrees")
    if target.has("q"):
        target_q = tuple(math.radians(a) for a in target.numbers("q", unit="degrees"))
    else:
        move = target.numbers("move", unit="degrees")
        start = plant.q0 if plant.q0 is not None else (0.0,) * len(move)
        if len(move) != len(start):
            raise target.error("move", f"has {len(move)} values for {len(start)} initial joint angles; allowed: one per joint")
        target_q = tuple(a + math.radians(b) for a, b in zip(start, move))
    target.finish()
    noise = r.table_of("noise", {})
    enabled, seed = noise.boolean("enabled", False), noise.integer("seed", 0, low=0)
    noise.finish()
    metrics = r.table_of("metrics", {})
    settle = metrics.nonnegative("settle_allowance", 2.0, unit="s")
    band = metrics.positive("band", 1e-3, unit="m")
    metrics.finish()
    r.finish()
    if settle >= plant.duration:
        raise r.error("metrics.settle_allowance", f"value {settle!r} leaves no residual window; allowed: < duration ({plant.duration:g} s)")
    return ClosedLoopScene(plant, target_q, controller, design_payload, cf, enabled, seed, settle, band)
