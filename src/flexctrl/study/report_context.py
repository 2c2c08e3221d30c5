"""What the study report's sections share: the report's context and small formatting helpers."""

from __future__ import annotations

import dataclasses
import math
import re
import statistics
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.study.column_units import metric_info, with_unit
from flexctrl.study.plan import ReportSpec
from flexctrl.study.store import FIXED_AFTER_COORDS, FIXED_TAIL, ResultStore, Table


def fmt(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        if not math.isfinite(value):
            return str(value)
        if value == int(value) and abs(value) < 1e6:
            return f"{value:g}"
        return f"{value:.4g}"
    return str(value).replace("|", "\\|")


def slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "x"


def median(values: Sequence[Any]) -> float | None:
    numbers = [v for v in values if isinstance(v, (int, float)) and math.isfinite(v)]
    return statistics.median(numbers) if numbers else None


def sort_key(value: Any) -> tuple:
    return (0, value, "") if isinstance(value, (int, float)) else (1, 0, str(value))


def md_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(fmt(v) for v in row) + " |" for row in rows]
    return lines


@dataclasses.dataclass
class ReportContext:
    """A study's result folder, its table and report settings, as the sections read them."""

    store: ResultStore
    table: Table
    study: dict
    spec: ReportSpec
    coords: list[str]
    metrics: list[str]
    metric: str | None
    figures: Path

    def distinct(self, column: str, rows: Sequence[dict] | None = None) -> list[Any]:
        values = {row.get(column) for row in (self.table.rows if rows is None else rows)} - {None}
        return sorted(values, key=sort_key)

    def ok_rows(self) -> list[dict]:
        return [row for row in self.table.rows if row["status"] == "ok"]

    @property
    def lower_is_better(self) -> bool:
        """The report metric's direction: the study's ``lower_is_better``, else the metric's."""
        return self.spec.lower_is_better is not False

    def diverged_rows(self) -> list[dict]:
        """The ok rows of runs that diverged (a finite ``divergence_time``)."""
        return [row for row in self.ok_rows() if diverged(row)]

    def ranked_rows(self) -> list[dict]:
        """The rows rankings, maps and worst cases compare: the ok runs, without the diverged
        ones unless the metric judges the whole run (``stable`` ...)."""
        info = None if self.metric is None else metric_info(self.metric)
        keep_diverged = info is not None and info.verdict
        return [row for row in self.ok_rows() if keep_diverged or not diverged(row)]


def diverged(row: dict) -> bool:
    """Whether a study row is of a run that diverged (a finite ``divergence_time``)."""
    value = row.get("divergence_time")
    return isinstance(value, (int, float)) and math.isfinite(value)


def columns(table: Table) -> tuple[list[str], list[str]]:
    cols = table.columns
    first, last = cols.index(FIXED_AFTER_COORDS[0]), cols.index(FIXED_AFTER_COORDS[-1])
    tail = cols.index(FIXED_TAIL[0])
    return cols[1:first], cols[last + 1 : tail]


def cell_medians(
    ctx: ReportContext, members: Sequence[dict], xs, ys, x_axis: str, y_axis: str
) -> np.ndarray:
    """Median metric (table units) per (y, x) cell of ``members``; NaN where no ok run has a
    value."""
    grid = np.full((len(ys), len(xs)), np.nan)
    cells: dict[tuple, list] = {}
    for r in members:
        if r.get(x_axis) in xs and r.get(y_axis) in ys:
            cells.setdefault((ys.index(r[y_axis]), xs.index(r[x_axis])), []).append(
                r.get(ctx.metric)
            )
    for (i, j), values in cells.items():
        m = median(values)
        grid[i, j] = np.nan if m is None else m
    return grid


def facet_title(facets: Sequence[str], combo: Sequence[Any]) -> str:
    return ", ".join(with_unit(f, v) for f, v in zip(facets, combo)) or "all runs"


__all__ = [
    "ReportContext",
    "cell_medians",
    "columns",
    "diverged",
    "facet_title",
    "fmt",
    "md_table",
    "median",
    "slug",
    "sort_key",
]
