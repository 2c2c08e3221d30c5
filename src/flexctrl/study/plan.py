"""The plan of a study as plain frozen data: its runs, axes and report settings (read by
:mod:`flexctrl.study.study_file`)."""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from typing import Any

SETTINGS = ("scene", "model", "controller", "payload", "configuration", "fidelity")
FILE_SETTINGS = ("scene", "model", "controller")
TARGETS = ("scene", "controller", "model")
PLOTS = ("maps", "ranking", "worst", "timing", "failures")
RESERVED_COLUMNS = (
    "run_id",
    "seed",
    "status",
    "error",
    "wall_time_s",
    "peak_memory_mb",
    "bytes_written",
    "worker",
)
MAX_RUNS = 1_000_000
NO_CONTROLLER = "none"


@dataclass(frozen=True)
class RunSpec:
    """One run of a study: its id, its grid coordinates and its settings.

    The settings are kept as canonical JSON so the object is truly immutable;
    :attr:`settings` returns a fresh dict every time.
    """

    index: int
    run_id: str
    coords: tuple[tuple[str, Any], ...]
    settings_json: str

    @property
    def settings(self) -> dict[str, Any]:
        """The settings handed to the executor (a fresh copy)."""
        return json.loads(self.settings_json)

    @property
    def coordinates(self) -> dict[str, Any]:
        """Grid coordinates by table column."""
        return dict(self.coords)


@dataclass(frozen=True)
class Axis:
    """One grid axis: the key as written and its validated values."""

    key: str
    values: tuple[Any, ...]


@dataclass(frozen=True)
class ReportSpec:
    """What the report shows (see the module docstring, ``[report]``)."""

    metric: str | None = None
    lower_is_better: bool | None = None
    map_axes: tuple[str, str] | None = None
    facet: tuple[str, ...] | None = None
    rank_by: str | None = None
    group_by: str | None = None
    worst: int = 3
    signals: tuple[str, ...] | None = None
    time: str = "t"
    timing: tuple[str, ...] | None = None
    plots: tuple[str, ...] = PLOTS

    def to_dict(self) -> dict[str, Any]:
        """Plain data (lists for tuples), for ``study.json``."""
        return {
            k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items()
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ReportSpec:
        """The inverse of :meth:`to_dict` (unknown keys ignored)."""
        names = {f.name for f in dataclasses.fields(cls)}
        kwargs: dict[str, Any] = {
            k: tuple(v) if isinstance(v, list) else v for k, v in data.items() if k in names
        }
        return cls(**kwargs)


@dataclass(frozen=True)
class StudySpec:
    """A validated study with its expanded runs.

    Attributes
    ----------
    name, source, root, sha256
        Study name, study file, its folder (absolute) and the file's digest.
    executor : str
        Registered executor name.
    seed, replicates : int
    metrics : tuple of str or None
        Metric columns asked for (None: whatever the executor returns).
    keep_trajectories : bool
    decimation : int
        Keep every ``decimation``-th trajectory sample.
    fixed : tuple of (key, value)
        Fixed settings as written (paths absolute).
    axes : tuple of Axis
    columns : tuple of str
        Coordinate columns of the table, in order.
    report : ReportSpec
    runs : tuple of RunSpec
        In grid order (the first axis varies slowest).
    unavailable : tuple of (run index, metric, reason)
        The study's metrics a run cannot produce (found before any run, by the executor's
        ``unavailable_metrics``): empty cells with their reason, not failed runs.
    """

    name: str
    source: str
    root: str
    sha256: str
    executor: str
    seed: int
    replicates: int
    metrics: tuple[str, ...] | None
    keep_trajectories: bool
    decimation: int
    fixed: tuple[tuple[str, Any], ...]
    axes: tuple[Axis, ...]
    columns: tuple[str, ...]
    report: ReportSpec
    runs: tuple[RunSpec, ...] = field(repr=False)
    unavailable: tuple[tuple[int, str, str], ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """The study as plain data (for ``study.json``)."""
        return {
            "name": self.name,
            "source": self.source,
            "sha256": self.sha256,
            "executor": self.executor,
            "seed": self.seed,
            "replicates": self.replicates,
            "metrics": None if self.metrics is None else list(self.metrics),
            "trajectories": {"keep": self.keep_trajectories, "decimation": self.decimation},
            "fixed": dict(self.fixed),
            "grid": {axis.key: list(axis.values) for axis in self.axes},
            "columns": list(self.columns),
            "report": self.report.to_dict(),
            "n_runs": len(self.runs),
            "unavailable": [list(entry) for entry in self.unavailable],
        }

    def unavailable_notes(self) -> list[str]:
        """One line per metric and reason: how many runs leave that cell empty, and why."""
        counts: dict[tuple[str, str], int] = {}
        for _, metric, reason in self.unavailable:
            counts[(metric, reason)] = counts.get((metric, reason), 0) + 1
        return [
            f"{metric} stays empty in {n} of {len(self.runs)} runs: {reason}"
            for (metric, reason), n in counts.items()
        ]


# -- values ----------------------------------------------------------------------------


def toml_literal(value: Any) -> str:
    """``value`` written as a TOML value, so ``parse_value(toml_literal(v)) == v``.

    Examples
    --------
    >>> toml_literal([1, 2.5, "a", True])
    '[1, 2.5, "a", true]'
    """
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value + 0.0)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_literal(v) for v in value) + "]"
    if isinstance(value, dict):
        return (
            "{" + ", ".join(f"{json.dumps(k)} = {toml_literal(v)}" for k, v in value.items()) + "}"
        )
    raise TypeError(f"{value!r} of type {type(value).__name__} has no TOML spelling here")
