"""Tuning files (``studies/tune_*.toml``): which controller keys to tune, on what, for what.

Layout (paths relative to the tuning file; SI units, angles in degrees as in every file)::

    name = "tune_lqr"                        # default: the file's stem
    controller = "../controllers/lqr.toml"   # the file to start from (its values: the start)

    [[parameters]]                           # one table per tuned key
    key = "weights.joint_deg"                # a key of the controller file (dotted, as --set)
    low = 0.02                               # bounds, in the key's own unit
    high = 1.0
    scale = "log"                            # "log" (default; low > 0) or "linear"
    integer = false                          # true: rounded to whole numbers (e.g. horizon)
    step = 5e-4                              # optional: rounded to a multiple of step (a
                                             # sample time the scene's plant step divides)

    [scenarios]                              # a study in the study file syntax (executor
                                             # closed_loop): fixed settings, [scenarios.grid]
    scene = "scenes/move_joint1_30deg.toml"  # axes, [scenarios.set] ...
    model = "../models/subedi3link.toml"
    payload = 2.0
    [scenarios.grid]
    q2 = [0, 90]

    [objective]
    metric = "tip_residual_rms"              # a closed-loop metric (flexctrl.loop.metrics.METRICS)
    statistic = "median"                     # "median", "max" or "mean" over the scenarios

    [constraints]                            # a candidate breaking one is infeasible
                                             # (recorded, never a crash)
    stable = true                            # stable = 1, settled_within_band = 1 everywhere
    torque_limits = true                     # no applied torque beyond its joint's limit
    closed_loop_radius = 1.0                 # the linear closed-loop spectral radius below
                                             # this, wherever the controller has a full-state
                                             # gain (omit to not check)
    real_time = true                         # controller_time_p95 below its sample time

    [optimizer]
    method = "differential_evolution"        # "differential_evolution" | "cma" | "nelder_mead"
    evaluations = 60                         # candidates in all (the budget)
    population = 8                           # candidates per generation, evaluated in parallel
    seed = 1

The scenario study and the metric names are checked by :mod:`flexctrl.tuning` (they need
the study and closed-loop layers); everything here is plain data checked on reading, and
each parameter key is checked against the controller file itself, so a key no
controller has is refused before any run.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flexctrl.errors import SpecError, keyword_checked
from flexctrl.spec import shipped
from flexctrl.spec.controller_reader import load_controller
from flexctrl.spec.overrides import apply_overrides
from flexctrl.spec.reader import TableReader, read_toml

SCALES = ("log", "linear")
STATISTICS = ("median", "max", "mean")
METHODS = ("differential_evolution", "cma", "nelder_mead")


@dataclass(frozen=True)
class ParameterSpec:
    """One tuned key of the controller file.

    Attributes
    ----------
    key : str
        Dotted key of the controller file (``weights.joint_deg``).
    low, high : float
        Bounds in the key's unit (degrees for ``*_deg`` keys).
    scale : {"log", "linear"}
        The optimiser searches ``log10(value)`` or the value itself.
    integer : bool
        Round to a whole number before use.
    step : float or None
        Round to a multiple of ``step`` before use (e.g. sample times the plant step divides).
    initial : float
        The controller file's own value (the start of the search), clipped to the bounds.
    """

    key: str
    low: float
    high: float
    scale: str = "log"
    integer: bool = False
    initial: float | None = None
    step: float | None = None

    def to_unit(self, value: float) -> float:
        """The value in the optimiser's coordinate (log10 or linear)."""
        return math.log10(value) if self.scale == "log" else float(value)

    def from_unit(self, coordinate: float) -> float:
        """The key's value for an optimiser coordinate: clipped to the bounds, to 6 digits.

        Six significant digits (what a file shows; the runs use exactly the value written),
        whole for integers.
        """
        value = 10.0**coordinate if self.scale == "log" else float(coordinate)
        value = min(max(float(f"{value:.6g}"), self.low), self.high)
        quantum = 1.0 if self.integer else self.step
        if quantum is not None:  # the nearest multiple inside the bounds
            lowest, highest = (
                math.ceil(self.low / quantum - 1e-9),
                math.floor(self.high / quantum + 1e-9),
            )
            value = float(f"{min(max(round(value / quantum), lowest), highest) * quantum:.12g}")
        return value


@dataclass(frozen=True)
class ObjectiveSpec:
    """What is minimised: ``statistic`` of ``metric`` over the scenarios."""

    metric: str = "tip_residual_rms"
    statistic: str = "median"


@dataclass(frozen=True)
class ConstraintSpec:
    """What makes a candidate infeasible (see the module docstring)."""

    stable: bool = True
    torque_limits: bool = True
    closed_loop_radius: float | None = 1.0
    real_time: bool = False


@dataclass(frozen=True)
class OptimizerSpec:
    """The optimiser, its budget and its seed."""

    method: str = "differential_evolution"
    evaluations: int = 60
    population: int = 8
    seed: int = 0


@dataclass(frozen=True)
class TuningSpec:
    """A validated tuning file; ``scenarios`` is the raw study document (validated by the tuner)."""

    name: str
    source: str
    base_dir: Path
    controller: Path
    parameters: tuple[ParameterSpec, ...]
    scenarios: dict[str, Any]
    objective: ObjectiveSpec
    constraints: ConstraintSpec
    optimizer: OptimizerSpec

    def settings(self) -> dict[str, Any]:
        """Plain JSON-ready data."""
        return {
            "name": self.name,
            "source": self.source,
            "controller": str(self.controller),
            "parameters": [
                {
                    "key": p.key,
                    "low": p.low,
                    "high": p.high,
                    "scale": p.scale,
                    "integer": p.integer,
                    "step": p.step,
                    "initial": p.initial,
                }
                for p in self.parameters
            ],
            "objective": {"metric": self.objective.metric, "statistic": self.objective.statistic},
            "constraints": {
                "stable": self.constraints.stable,
                "torque_limits": self.constraints.torque_limits,
                "closed_loop_radius": self.constraints.closed_loop_radius,
                "real_time": self.constraints.real_time,
            },
            "optimizer": {
                "method": self.optimizer.method,
                "evaluations": self.optimizer.evaluations,
                "population": self.optimizer.population,
                "seed": self.optimizer.seed,
            },
        }


@keyword_checked
def load_tuning(path: str | Path, overrides: Iterable[str] = ()) -> TuningSpec:
    """Read and validate a tuning file (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The tuning file.
    overrides : iterable of str
        ``KEY=VALUE`` strings applied first (``optimizer.evaluations=10``).

    Returns
    -------
    TuningSpec

    Raises
    ------
    SpecError
        Naming the file, the key, the value and what is allowed: a parameter key the
        controller file does not have, reversed or non-positive log bounds, a missing or
        empty scenario table, an unknown statistic or optimiser.
    """
    path = shipped.find(path, "tuning")
    source = str(path)
    document = apply_overrides(read_toml(path), overrides, source=f"{source} (--set)")
    base = path.resolve().parent
    r = TableReader(document, source)
    name = r.string("name", path.stem)
    controller = _controller_file(r, base)
    parameters = _parameters(r, controller)
    scenarios = r.raw("scenarios", None)
    if not isinstance(scenarios, dict) or not scenarios:
        raise r.error(
            "scenarios",
            f"value {scenarios!r} is not allowed; allowed: a [scenarios] table in the study "
            "file syntax (scene, model, payload, [scenarios.grid] ...)",
        )
    o = r.table_of("objective", {})
    objective = ObjectiveSpec(
        o.string("metric", "tip_residual_rms"), o.string("statistic", "median", choices=STATISTICS)
    )
    o.finish()
    constraints = _constraints(r.table_of("constraints", {}))
    optimizer = _optimizer(r.table_of("optimizer", {}))
    r.finish()
    return TuningSpec(
        name,
        source,
        base,
        controller,
        parameters,
        copy.deepcopy(scenarios),
        objective,
        constraints,
        optimizer,
    )


def _controller_file(r: TableReader, base: Path) -> Path:
    """``controller``: the controller file tuned, relative to the tuning file."""
    controller_name = r.string("controller")
    controller = (base / controller_name).resolve()
    if not controller.is_file():
        raise r.error(
            "controller", f"file {controller_name!r} not found (looked at '{controller}')"
        )
    return controller


def _parameters(r: TableReader, controller: Path) -> tuple[ParameterSpec, ...]:
    """``[[parameters]]``: one or more, each key once, each a numeric key of the controller."""
    controller_document = read_toml(controller)
    raw = r.raw("parameters", None)
    if not isinstance(raw, list) or not raw or not all(isinstance(t, dict) for t in raw):
        raise r.error(
            "parameters",
            f"value {raw!r} is not allowed; allowed: one or more [[parameters]] tables "
            "with key, low, high",
        )
    parameters = []
    for i, table in enumerate(raw):
        p = TableReader(table, r.source, prefix=f"parameters[{i + 1}]")
        parameters.append(_parameter(p, controller, controller_document))
        p.finish()
    keys = [p.key for p in parameters]
    if len(set(keys)) != len(keys):
        raise r.error("parameters", f"tunes a key twice ({keys}); allowed: each key once")
    return tuple(parameters)


def _constraints(c: TableReader) -> ConstraintSpec:
    """``[constraints]``: what a candidate must satisfy."""
    constraints = ConstraintSpec(
        stable=c.boolean("stable", True),
        torque_limits=c.boolean("torque_limits", True),
        closed_loop_radius=c.positive("closed_loop_radius", unit="spectral radius")
        if c.has("closed_loop_radius")
        else None,
        real_time=c.boolean("real_time", False),
    )
    c.finish()
    return constraints


def _optimizer(m: TableReader) -> OptimizerSpec:
    """``[optimizer]``: the method, the evaluations, the population and the seed."""
    optimizer = OptimizerSpec(
        m.string("method", "differential_evolution", choices=METHODS),
        m.integer("evaluations", 60, low=1, high=100_000),
        m.integer("population", 8, low=2, high=1000),
        m.integer("seed", 0, low=0),
    )
    m.finish()
    return optimizer


def _parameter(p: TableReader, controller: Path, controller_document: dict) -> ParameterSpec:
    key = p.string("key")
    scale = p.string("scale", "log", choices=SCALES)
    integer = p.boolean("integer", False)
    low, high = p.number("low"), p.number("high")
    if not low < high:
        raise p.error("high", f"value {high!r} is not above low = {low!r}; allowed: low < high")
    step = p.positive("step") if p.has("step") else None
    if step is not None and (math.ceil(low / step - 1e-9) * step > high + 1e-12 * abs(high)):
        raise p.error(
            "step",
            f"value {step!r} leaves no multiple within [{low!r}, {high!r}]; allowed: a smaller "
            "step",
        )
    if scale == "log" and low <= 0:
        raise p.error(
            "low",
            f"value {low!r} is not allowed with scale = 'log'; allowed: low > 0, or scale = "
            "'linear'",
        )
    initial = _file_value(controller_document, key)
    if initial is not None and (isinstance(initial, bool) or not isinstance(initial, (int, float))):
        raise p.error(
            "key",
            f"value {key!r} names a {type(initial).__name__} in '{controller}' "
            f"({initial!r}); allowed: a numeric key",
        )
    probe = low if scale == "linear" else math.sqrt(low * high)
    try:  # the key must exist for this controller kind and accept a value in the bounds
        load_controller(controller, [f"{key}={round(probe) if integer else probe!r}"])
    except SpecError as exc:
        raise p.error(
            "key", f"value {key!r} is not a key the controller file '{controller}' accepts: {exc}"
        ) from None
    if initial is not None:
        initial = min(max(float(initial), low), high)
    return ParameterSpec(key, float(low), float(high), scale, integer, initial, step)


def _file_value(document: dict, key: str) -> Any:
    """The file's value of a dotted key; ``name[i]`` is the i-th (1-based) entry of a list."""
    node: Any = document
    for part in key.split("."):
        name, _, index = part.partition("[")
        if not isinstance(node, dict) or name not in node:
            return None
        node = node[name]
        if index:
            i = int(index.rstrip("]")) if index.rstrip("]").isdigit() else 0
            if not isinstance(node, list) or not 1 <= i <= len(node):
                return None
            node = node[i - 1]
    return node
