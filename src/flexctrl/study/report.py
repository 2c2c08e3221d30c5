"""The study report: ``report.md`` and PNG figures, drawn from the result folder alone.

Reads ``results.csv``, ``study.json`` and ``runs/*.npz`` (rebuilding
``results.csv`` from ``plan.jsonl`` and the records if it is missing, e.g.
after a kill) and writes ``DIR/report.md`` with figures in ``DIR/figures/``:

maps
    A heat map of the report metric over two grid columns (default ``q2`` and
    ``q3``: the residual-vibration map over the configuration), one panel per
    combination of the facet columns (default: every other column that
    varies, e.g. payload and controller), cells the median over anything
    else that varies (replicates), one colour scale for all panels.
ranking
    Per value of ``group_by`` (payload), the ``rank_by`` values (controllers)
    sorted by the median of the metric over their ok runs.
worst
    The ``worst`` ok runs by the metric, with their stored trajectories.
timing
    Per ``rank_by`` value: median wall time of a run and the median of every
    computing-time metric (``controller_time_median`` ...).
failures
    Every failed run with its error text; runs of the plan not yet recorded.

Nothing here runs a simulation, so ``flexctrl report DIR`` redraws the report
after the fact, with other options if wished.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import re
import statistics
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.errors import SpecError
from flexctrl.study.column_units import display, with_unit
from flexctrl.study.report_figures import (
    TEXT_CELLS,
    draw_best_map,
    draw_ranking,
    draw_signals,
    draw_value_maps,
    wants_log,
)
from flexctrl.study.store import FIXED_AFTER_COORDS, FIXED_TAIL, ResultStore, Table, atomic_write
from flexctrl.study.plan import ReportSpec

TIMING = re.compile(r"(controller|solve|solver|step|compute|cpu|qp|nlp)_?time", re.IGNORECASE)
MAX_PANELS = 12


def _fmt(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        if not math.isfinite(value):
            return str(value)
        if value == int(value) and abs(value) < 1e6:
            return f"{value:g}"
        return f"{value:.4g}"
    return str(value).replace("|", "\\|")


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "x"


def _median(values: Sequence[Any]) -> float | None:
    numbers = [v for v in values if isinstance(v, (int, float)) and math.isfinite(v)]
    return statistics.median(numbers) if numbers else None


def _sort_key(value: Any) -> tuple:
    return (0, value, "") if isinstance(value, (int, float)) else (1, 0, str(value))


def _md_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(_fmt(v) for v in row) + " |" for row in rows]
    return lines


@dataclasses.dataclass
class _Context:
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
        return sorted(values, key=_sort_key)

    def ok_rows(self) -> list[dict]:
        return [row for row in self.table.rows if row["status"] == "ok"]


def _columns(table: Table) -> tuple[list[str], list[str]]:
    cols = table.columns
    first, last = cols.index(FIXED_AFTER_COORDS[0]), cols.index(FIXED_AFTER_COORDS[-1])
    tail = cols.index(FIXED_TAIL[0])
    return cols[1:first], cols[last + 1 : tail]


def write_report(
    directory: str | Path,
    *,
    metric: str | None = None,
    map_axes: Sequence[str] | None = None,
    worst: int | None = None,
) -> Path:
    """Draw ``report.md`` and its figures from the files in ``directory``.

    Parameters
    ----------
    directory
        A study's result folder.
    metric, map_axes, worst
        Override the study's ``[report]`` settings.

    Returns
    -------
    Path
        ``directory/report.md``.

    Raises
    ------
    SpecError
        If the folder holds no study, or an override names an unknown column.
    """
    store = ResultStore(directory)
    study = store.read_study()
    if study is None:
        raise SpecError(
            f"'{store.dir}' holds no study.json; allowed: a folder written by 'flexctrl study'",
            key="DIR",
        )
    if not store.table_path.is_file():
        store.write_table(
            study.get("study", {}).get("columns"), study.get("study", {}).get("metrics")
        )
    table = store.read_table()
    spec = ReportSpec.from_dict(study.get("study", {}).get("report", {}))
    coords, metrics = _columns(table)
    if metric is not None:
        if metric not in metrics:
            raise SpecError(
                f"'{metric}' is not a metric of this study; allowed: {', '.join(metrics) or '(none recorded)'}",
                key="--metric",
            )
        spec = dataclasses.replace(spec, metric=metric)
    if map_axes is not None:
        for axis in map_axes:
            if axis not in coords:
                raise SpecError(
                    f"'{axis}' is not a grid column; allowed: {', '.join(coords)}", key="--map-axes"
                )
        spec = dataclasses.replace(spec, map_axes=tuple(map_axes))
    if worst is not None:
        spec = dataclasses.replace(spec, worst=worst)
    chosen = spec.metric if spec.metric in metrics else (metrics[0] if metrics else None)
    figures = store.dir / "figures"
    figures.mkdir(exist_ok=True)
    for old in figures.glob("*.png"):
        old.unlink()
    ctx = _Context(store, table, study, spec, coords, metrics, chosen, figures)

    lines = _header(ctx)
    sections = {
        "maps": _maps,
        "ranking": _ranking,
        "worst": _worst,
        "timing": _timing,
        "failures": _failures,
    }
    for name in spec.plots:
        lines += ["", *sections[name](ctx)]
    if "failures" not in spec.plots:
        lines += ["", *_failures(ctx)]
    lines += _executor_sections(ctx)
    path = store.dir / "report.md"
    atomic_write(path, ("\n".join(lines) + "\n").encode())
    return path


def _executor_sections(ctx: _Context) -> list[str]:
    """The executor's own report sections (its ``report`` hook), if it has one."""
    from flexctrl.study.registry import get_executor

    name = ctx.study.get("study", {}).get("executor")
    try:
        hook = get_executor(name).report if name else None
    except SpecError:
        return []
    if hook is None:
        return []
    extra = hook(ctx.store.dir, ctx.table.rows, ctx.figures)
    return ["", *extra] if extra else []


def _header(ctx: _Context) -> list[str]:
    s = ctx.study.get("study", {})
    statuses = [row["status"] for row in ctx.table.rows]
    n_plan = s.get("n_runs", len(statuses))
    ok, failed = statuses.count("ok"), statuses.count("failed")
    versions = ctx.study.get("versions", {})
    machine = ctx.study.get("machine", {})
    lines = [
        f"# Study `{s.get('name', '?')}`",
        "",
        f"- study file: `{s.get('source', '?')}` (sha256 {s.get('sha256', '?')}), executor "
        f"`{s.get('executor', '?')}`, seed {s.get('seed', '?')}",
        f"- runs: {n_plan} in the grid; {ok} ok, {failed} failed, {max(n_plan - ok - failed, 0)} "
        "not run",
        "- grid: "
        + (", ".join(f"{k} ({len(v)})" for k, v in s.get("grid", {}).items()) or "a single run"),
        f"- report metric: `{ctx.metric}` ({'lower' if ctx.spec.lower_is_better else 'higher'} "
        "is better)"
        if ctx.metric
        else "- no metric recorded yet",
        f"- started {ctx.study.get('start', '?')}, ended "
        f"{ctx.study.get('end') or 'not yet (interrupted or running)'}; "
        f"{len(ctx.study.get('sessions', []))} session(s), last on {ctx.study.get('sessions', [{}])[-1].get('backend', '?')}",
        f"- machine: {machine.get('platform', '?')}, {machine.get('cpu_count', '?')} CPUs",
        "- versions: " + ", ".join(f"{k} {v}" for k, v in versions.items()),
        "",
        "Files: `results.csv` (one row per run), `runs/<id>.json` (records), `runs/<id>.npz` "
        "(trajectories), `study.json`.",
    ]
    return lines


def _map_axes(ctx: _Context) -> tuple[str, str] | None:
    if ctx.spec.map_axes:
        return tuple(ctx.spec.map_axes)  # type: ignore[return-value]
    varying = [c for c in ctx.coords if c != "replicate" and len(ctx.distinct(c)) > 1]
    if "q2" in varying and "q3" in varying:
        return ("q2", "q3")
    numeric = [c for c in varying if all(isinstance(v, float) for v in ctx.distinct(c))]
    return (numeric[0], numeric[1]) if len(numeric) >= 2 else None


def _cell_medians(
    ctx: _Context, members: Sequence[dict], xs, ys, x_axis: str, y_axis: str
) -> np.ndarray:
    """Median metric (table units) per (y, x) cell of ``members``; NaN where no ok run has a value."""
    grid = np.full((len(ys), len(xs)), np.nan)
    cells: dict[tuple, list] = {}
    for r in members:
        if r.get(x_axis) in xs and r.get(y_axis) in ys:
            cells.setdefault((ys.index(r[y_axis]), xs.index(r[x_axis])), []).append(
                r.get(ctx.metric)
            )
    for (i, j), values in cells.items():
        m = _median(values)
        grid[i, j] = np.nan if m is None else m
    return grid


def _facet_title(facets: Sequence[str], combo: Sequence[Any]) -> str:
    return ", ".join(with_unit(f, v) for f, v in zip(facets, combo)) or "all runs"


def _maps(ctx: _Context) -> list[str]:
    lines = ["## Maps"]
    axes = _map_axes(ctx)
    if ctx.metric is None or axes is None:
        return lines + [
            "",
            "No map: it needs a metric and two grid columns that vary (set `[report] map_axes`).",
        ]
    x_axis, y_axis = axes
    facets = (
        list(ctx.spec.facet)
        if ctx.spec.facet
        else [
            c for c in ctx.coords if c not in axes and c != "replicate" and len(ctx.distinct(c)) > 1
        ]
    )
    rows = ctx.ok_rows()
    xs, ys = ctx.distinct(x_axis), ctx.distinct(y_axis)
    shown = display(ctx.metric)
    panels = []
    for combo in itertools.product(*(ctx.distinct(f) for f in facets)):
        members = [r for r in rows if all(r.get(f) == v for f, v in zip(facets, combo))]
        panels.append(
            (
                _facet_title(facets, combo),
                shown.scale * _cell_medians(ctx, members, xs, ys, x_axis, y_axis),
            )
        )
    finite = np.concatenate([g[np.isfinite(g)] for _, g in panels]) if panels else np.array([])
    if finite.size == 0:
        return lines + ["", f"No map: no ok run has a finite `{ctx.metric}`."]
    log = wants_log(finite)
    lines += [
        "",
        f"Median {shown.label} over ({display(x_axis).label}, {display(y_axis).label}), one "
        "panel per "
        f"{' x '.join(f'`{f}`' for f in facets) or 'study'}; one "
        f"{'logarithmic ' if log else ''}colour scale for all "
        f"panels ({_fmt(float(finite.min()))} to "
        f"{_fmt(float(finite.max()))}{' ' + shown.unit if shown.unit else ''}), grey: no ok run.",
    ]
    last = len(ctx.distinct(facets[-1])) if facets else 1
    for page in range(0, len(panels), MAX_PANELS):
        name = (
            f"map_{_slug(ctx.metric)}"
            + (f"_{page // MAX_PANELS + 1}" if len(panels) > MAX_PANELS else "")
            + ".png"
        )
        draw_value_maps(
            ctx.figures / name,
            panels[page : page + MAX_PANELS],
            xs,
            ys,
            x_axis,
            y_axis,
            shown.label,
            last if 1 < last <= 4 else 3,
        )
        lines += ["", f"![map]({ctx.figures.name}/{name})"]
    return lines + _best_maps(ctx, facets, xs, ys, x_axis, y_axis)


def _best_maps(ctx: _Context, facets: list[str], xs, ys, x_axis: str, y_axis: str) -> list[str]:
    """Which ``rank_by`` value is best in each cell, and every value's ratio to that best."""
    rank_by = ctx.spec.rank_by
    candidates = ctx.distinct(rank_by) if rank_by in ctx.coords else []
    if len(candidates) < 2 or rank_by in (x_axis, y_axis):
        return []
    others = [f for f in facets if f != rank_by]
    shown = display(ctx.metric)
    sign = 1.0 if ctx.spec.lower_is_better else -1.0
    best_panels, ratio_panels, binary = [], [], True
    for combo in itertools.product(*(ctx.distinct(f) for f in others)):
        members = [r for r in ctx.ok_rows() if all(r.get(f) == v for f, v in zip(others, combo))]
        grids = {
            c: _cell_medians(
                ctx, [r for r in members if r.get(rank_by) == c], xs, ys, x_axis, y_axis
            )
            for c in candidates
        }
        stack = np.stack([grids[c] for c in candidates])
        binary &= bool(np.all(np.isin(stack[np.isfinite(stack)], (0.0, 1.0))))
        cells = [[None] * len(xs) for _ in ys]
        best = np.full((len(ys), len(xs)), np.nan)
        for i, j in itertools.product(range(len(ys)), range(len(xs))):
            values = {
                c: stack[k, i, j] for k, c in enumerate(candidates) if np.isfinite(stack[k, i, j])
            }
            if values:
                best[i, j] = min(values.values(), key=lambda v: sign * v)
                winners = [
                    c
                    for c, v in values.items()
                    if math.isclose(v, best[i, j], rel_tol=1e-9, abs_tol=1e-300)
                ]
                cells[i][j] = (winners, shown.scale * best[i, j])
        title = _facet_title(others, combo)
        best_panels.append((title, cells))
        with np.errstate(divide="ignore", invalid="ignore"):
            for c in candidates:
                ratio = grids[c] / best if sign > 0 else best / grids[c]
                ratio_panels.append(
                    (f"{with_unit(rank_by, c)}" + (f"; {title}" if others else ""), ratio)
                )
    written = len(xs) * len(ys) <= TEXT_CELLS
    lines = [
        "",
        "### Best per cell",
        "",
        f"The `{rank_by}` with the {'lowest' if sign > 0 else 'highest'} median {shown.label} in "
        "each cell "
        + (
            "(its value written below its name; hatched: a tie, every tied name listed)."
            if written
            else f"(colour: the best, named in the legend; hatched: a tie; {len(xs)} x {len(ys)} "
            "cells leave no room "
            "for names and values, which the ranking above and the ratio maps below give)."
        ),
    ]
    name = f"best_{_slug(ctx.metric)}.png"
    draw_best_map(
        ctx.figures / name,
        best_panels,
        candidates,
        xs,
        ys,
        x_axis,
        y_axis,
        shown,
        min(3, len(best_panels)),
    )
    lines += ["", f"![best per cell]({ctx.figures.name}/{name})"]
    ratios = np.concatenate([g[np.isfinite(g)] for _, g in ratio_panels])
    if binary or ratios.size == 0:
        return lines + [
            "",
            f"No ratio map: `{ctx.metric}` takes only the values 0 and 1, so the best map says "
            "it all."
            if binary
            else "No ratio map: no finite ratio.",
        ]
    name = f"ratio_{_slug(ctx.metric)}.png"
    draw_value_maps(
        ctx.figures / name,
        ratio_panels,
        xs,
        ys,
        x_axis,
        y_axis,
        f"{shown.label} / best of the cell" if sign > 0 else f"best of the cell / {shown.label}",
        len(candidates) if len(candidates) <= 6 else 4,
        ratio=True,
    )
    return lines + [
        "",
        f"Each `{rank_by}`'s median against the cell's best (×1: the best; "
        f"{'larger is worse' if sign > 0 else 'a zero value gives no ratio'}).",
        "",
        f"![ratio to the best]({ctx.figures.name}/{name})",
    ]


def _ranking(ctx: _Context) -> list[str]:
    lines = ["## Ranking"]
    rank_by, group_by = ctx.spec.rank_by, ctx.spec.group_by
    if ctx.metric is None or rank_by not in ctx.coords:
        return lines + [
            "",
            "No ranking: it needs a metric and a `rank_by` column (a controller axis by default).",
        ]
    groups = ctx.distinct(group_by) if group_by in ctx.coords else [None]
    candidates = ctx.distinct(rank_by)
    sign = 1 if ctx.spec.lower_is_better else -1
    shown = display(ctx.metric)
    lines += [
        "",
        f"Median {shown.label} of the ok runs per `{rank_by}`"
        + (f", for each `{group_by}`" if group_by in ctx.coords else "")
        + f"; best first ({'lowest' if sign > 0 else 'highest'}); min and max over the other "
        "grid columns (poses ...).",
    ]
    values: dict[Any, dict[Any, list[float]]] = {}
    for group in groups:
        members = [r for r in ctx.table.rows if group is None or r.get(group_by) == group]
        entries = []
        values[group] = {}
        for candidate in candidates:
            mine = [r for r in members if r.get(rank_by) == candidate]
            ok = [
                shown.value(r.get(ctx.metric))
                for r in mine
                if r["status"] == "ok" and isinstance(r.get(ctx.metric), float)
            ]
            values[group][candidate] = ok
            entries.append(
                (
                    candidate,
                    _median(ok),
                    min(ok, default=None),
                    max(ok, default=None),
                    len(ok),
                    len(mine) - len(ok),
                )
            )
        entries.sort(key=lambda e: (e[1] is None, sign * e[1] if e[1] is not None else 0.0))
        u = f" ({shown.unit})" if shown.unit else ""
        lines += [
            "",
            f"### {with_unit(group_by, group)}" if group is not None else "### all runs",
            "",
        ]
        lines += _md_table(
            [
                "rank",
                rank_by,
                f"median {shown.label}",
                f"min{u}",
                f"max{u}",
                "ok runs",
                "failed runs",
            ],
            [(i + 1, *entry) for i, entry in enumerate(entries)],
        )
    name = f"ranking_{_slug(ctx.metric)}.png"
    draw_ranking(ctx.figures / name, values, candidates, rank_by, group_by, shown)
    return lines + ["", f"![ranking]({ctx.figures.name}/{name})"]


def _worst(ctx: _Context) -> list[str]:
    lines = ["## Worst cases"]
    if ctx.metric is None or ctx.spec.worst <= 0:
        return lines + ["", "None asked for." if ctx.spec.worst <= 0 else "No metric recorded."]
    rows = [r for r in ctx.ok_rows() if isinstance(r.get(ctx.metric), float)]
    rows.sort(key=lambda r: r[ctx.metric], reverse=ctx.spec.lower_is_better)
    rows = rows[: ctx.spec.worst]
    if not rows:
        return lines + ["", "No ok run yet."]
    shown = display(ctx.metric)
    rank_by = ctx.spec.rank_by if ctx.spec.rank_by in ctx.coords else None
    lines += [
        "",
        f"The {len(rows)} ok runs with the "
        f"{'largest' if ctx.spec.lower_is_better else 'smallest'} {shown.label}"
        + (
            f", each drawn with every `{rank_by}` of its cell on the same axes (the worst one thicker)."
            if rank_by
            else "."
        ),
        "",
    ]
    lines += _md_table(
        ["rank", "run_id", *(display(c).label for c in ctx.coords), shown.label],
        [
            (i + 1, r["run_id"], *(r.get(c) for c in ctx.coords), shown.value(r[ctx.metric]))
            for i, r in enumerate(rows)
        ],
    )
    for i, row in enumerate(rows):
        cell = [c for c in ctx.coords if c != rank_by]
        neighbours = (
            [r for r in ctx.table.rows if all(r.get(c) == row.get(c) for c in cell)]
            if rank_by
            else [row]
        )
        neighbours.sort(key=lambda r: r["run_id"] != row["run_id"])
        stored = [(r, ctx.store.load_trajectories(r["run_id"])) for r in neighbours]
        stored = [(r, arrays) for r, arrays in stored if arrays]
        if not stored or stored[0][0]["run_id"] != row["run_id"]:
            lines += ["", f"Run `{row['run_id']}`: no stored trajectories."]
            continue
        name = f"worst_{i + 1}_{row['run_id']}.png"
        label = (lambda r: str(r.get(rank_by))) if rank_by else (lambda r: r["run_id"])
        title = (
            f"#{i + 1}: "
            + ", ".join(with_unit(c, row.get(c)) for c in cell)
            + f"; worst: {label(row)}, {shown.label} = {_fmt(shown.value(row[ctx.metric]))}"
        )
        _draw_cell(ctx, ctx.figures / name, stored, label, title, label(row))
        lines += ["", f"![run {row['run_id']}]({ctx.figures.name}/{name})"]
    return lines


def _draw_cell(ctx: _Context, path: Path, stored, label, title: str, highlight: str) -> None:
    """The closed loop's four panels (:func:`flexctrl.loop.compare_figure.draw_runs`) or any executor's signals."""
    time_name = ctx.spec.time
    if all(k in stored[0][1] for k in (time_name, "u1", "w1")) and not ctx.spec.signals:
        from flexctrl.loop.compare_figure import draw_runs

        curves = [_run_curves(ctx, row, arrays, label(row)) for row, arrays in stored]
        fig = draw_runs(curves, title=title, highlight=highlight)
        fig.savefig(path, dpi=100)
    else:
        draw_signals(
            path,
            [(label(row), arrays) for row, arrays in stored],
            ctx.spec.signals,
            time_name,
            title,
            highlight,
        )


def _run_curves(ctx: _Context, row: dict, arrays: dict[str, np.ndarray], label: str):
    """A closed-loop run's stored trajectories (``t``, ``e``, ``q<k>``, ``u<k>``, ``w<k>``) as curves."""
    from flexctrl.loop.compare_figure import RunCurves

    def stack(prefix: str) -> np.ndarray:
        names = [f"{prefix}{k}" for k in range(1, 100) if f"{prefix}{k}" in arrays]
        return (
            np.column_stack([arrays[n] for n in names])
            if names
            else np.zeros((len(arrays[ctx.spec.time]), 0))
        )

    time = arrays[ctx.spec.time]
    record = ctx.store.read_record(row["run_id"]) or {}
    metrics = record.get("metrics", {})
    limits = [metrics.get(f"torque_limit_{k}", math.inf) for k in range(1, stack("u").shape[1] + 1)]
    start = metrics.get("window_start")
    joints = stack("q")
    return RunCurves(
        label,
        time,
        arrays.get("e"),
        stack("w"),
        stack("u"),
        joints if joints.shape[1] else None,
        None,
        limits,
        None if start is None else (float(start), float(time[-1])),
        metrics.get("tip_residual_rms"),
    )


def _timing(ctx: _Context) -> list[str]:
    lines = ["## Timing"]
    timing = [
        m
        for m in (ctx.spec.timing or [m for m in ctx.metrics if TIMING.search(m)])
        if m in ctx.metrics
    ]
    by = ctx.spec.rank_by if ctx.spec.rank_by in ctx.coords else None
    groups = ctx.distinct(by) if by else [None]
    header = [
        by or "runs",
        "ok runs",
        "median wall time per run (s)",
        *[f"median {display(m).label}" for m in timing],
    ]
    rows = []
    for group in groups:
        ok = [r for r in ctx.ok_rows() if group is None or r.get(by) == group]
        rows.append(
            (
                group if group is not None else "all",
                len(ok),
                _median([r.get("wall_time_s") for r in ok]),
                *[display(m).value(_median([r.get(m) for r in ok])) for m in timing],
            )
        )
    lines += [
        "",
        "Wall time covers the whole run in its worker (build, design, simulation, metrics); "
        "a worker builds its model once, so its first run is slower.",
        "",
    ]
    return lines + _md_table(header, rows) + ["", *_resources(ctx)]


def _resources(ctx: _Context) -> list[str]:
    """Throughput per session, memory and disk per run: does the study stay flat as it grows?"""
    lines = ["### Resources", ""]
    sessions = [s for s in ctx.study.get("sessions", []) if s.get("elapsed_s")]
    if sessions:
        rows = []
        for number, s in enumerate(sessions, 1):
            ran = int(s.get("ok", 0)) + int(s.get("failed", 0))
            rate = 60.0 * ran / s["elapsed_s"] if s["elapsed_s"] > 0 else None
            rows.append(
                (
                    number,
                    s.get("backend", "?"),
                    ran,
                    s["elapsed_s"],
                    rate,
                    s.get("parent_peak_memory_mb"),
                )
            )
        lines += _md_table(
            [
                "session",
                "backend",
                "runs",
                "wall time (s)",
                "runs per minute",
                "parent peak memory (MB)",
            ],
            rows,
        ) + [""]
    memory = [
        r.get("peak_memory_mb")
        for r in ctx.table.rows
        if isinstance(r.get("peak_memory_mb"), (int, float))
    ]
    disk = [
        r.get("bytes_written")
        for r in ctx.table.rows
        if isinstance(r.get("bytes_written"), (int, float))
    ]
    if memory:
        lines.append(
            f"- worker peak resident memory when a run ended: median {_fmt(_median(memory))} MB, "
            f"max {_fmt(max(memory))} MB "
            "(a worker's high-water mark, so it bounds every run it did)"
        )
    if disk:
        lines.append(
            "- disk written per run (record and trajectory): median "
            f"{_fmt(_median(disk) / 1024)} KiB, "
            f"max {_fmt(max(disk) / 1024)} KiB, total {_fmt(sum(disk) / 2**20)} MiB over "
            f"{len(disk)} runs"
        )
    return lines


def _failures(ctx: _Context) -> list[str]:
    lines = ["## Failed runs"]
    failed = [r for r in ctx.table.rows if r["status"] == "failed"]
    if not failed:
        lines += ["", "None."]
    else:
        lines += ["", f"{len(failed)} run(s) failed; the others went on.", ""]
        lines += _md_table(
            ["run_id", *ctx.coords, "error"],
            [
                (r["run_id"], *(r.get(c) for c in ctx.coords), (r["error"] or "")[:300])
                for r in failed
            ],
        )
    recorded = {r["run_id"] for r in ctx.table.rows}
    pending = [p for p in ctx.store.iter_plan() if p["run_id"] not in recorded]
    if pending:
        lines += [
            "",
            f"{len(pending)} run(s) of the grid have no record yet (interrupted study): "
            "run `flexctrl study STUDY --out DIR --resume` to complete it.",
        ]
    return lines
