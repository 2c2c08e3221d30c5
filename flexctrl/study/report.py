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
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from flexctrl.errors import SpecError
from flexctrl.study.spec import ReportSpec
from flexctrl.study.store import FIXED_AFTER_COORDS, FIXED_TAIL, ResultStore, Table, atomic_write

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
    return cols[1:first], cols[last + 1:tail]


def write_report(directory: str | Path, *, metric: str | None = None, map_axes: Sequence[str] | None = None,
                 worst: int | None = None) -> Path:
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
        raise SpecError(f"'{store.dir}' holds no study.json; allowed: a folder written by 'flexctrl study'", key="DIR")
    if not store.table_path.is_file():
        store.write_table(study.get("study", {}).get("columns"), study.get("study", {}).get("metrics"))
    table = store.read_table()
    spec = ReportSpec.from_dict(study.get("study", {}).get("report", {}))
    coords, metrics = _columns(table)
    if metric is not None:
        if metric not in metrics:
            raise SpecError(f"'{metric}' is not a metric of this study; allowed: {', '.join(metrics) or '(none recorded)'}", key="--metric")
        spec = dataclasses.replace(spec, metric=metric)
    if map_axes is not None:
        for axis in map_axes:
            if axis not in coords:
                raise SpecError(f"'{axis}' is not a grid column; allowed: {', '.join(coords)}", key="--map-axes")
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
    sections = {"maps": _maps, "ranking": _ranking, "worst": _worst, "timing": _timing, "failures": _failures}
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
        f"- study file: `{s.get('source', '?')}` (sha256 {s.get('sha256', '?')}), executor `{s.get('executor', '?')}`, seed {s.get('seed', '?')}",
        f"- runs: {n_plan} in the grid; {ok} ok, {failed} failed, {max(n_plan - ok - failed, 0)} not run",
        f"- grid: " + (", ".join(f"{k} ({len(v)})" for k, v in s.get("grid", {}).items()) or "a single run"),
        f"- report metric: `{ctx.metric}` ({'lower' if ctx.spec.lower_is_better else 'higher'} is better)" if ctx.metric else "- no metric recorded yet",
        f"- started {ctx.study.get('start', '?')}, ended {ctx.study.get('end') or 'not yet (interrupted or running)'}; "
        f"{len(ctx.study.get('sessions', []))} session(s), last on {ctx.study.get('sessions', [{}])[-1].get('backend', '?')}",
        f"- machine: {machine.get('platform', '?')}, {machine.get('cpu_count', '?')} CPUs",
        "- versions: " + ", ".join(f"{k} {v}" for k, v in versions.items()),
        "",
        "Files: `results.csv` (one row per run), `runs/<id>.json` (records), `runs/<id>.npz` (trajectories), `study.json`.",
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


def _maps(ctx: _Context) -> list[str]:
    lines = ["## Maps"]
    axes = _map_axes(ctx)
    if ctx.metric is None or axes is None:
        return lines + ["", "No map: it needs a metric and two grid columns that vary (set `[report] map_axes`)."]
    x_axis, y_axis = axes
    facets = list(ctx.spec.facet) if ctx.spec.facet else [c for c in ctx.coords if c not in axes and c != "replicate" and len(ctx.distinct(c)) > 1]
    rows = ctx.ok_rows()
    xs, ys = ctx.distinct(x_axis), ctx.distinct(y_axis)
    combos = list(itertools.product(*(ctx.distinct(f) for f in facets)))
    panels = []
    for combo in combos:
        grid = np.full((len(ys), len(xs)), np.nan)
        members = [r for r in rows if all(r.get(f) == v for f, v in zip(facets, combo))]
        cells: dict[tuple, list] = {}
        for r in members:
            if r.get(x_axis) in xs and r.get(y_axis) in ys:
                cells.setdefault((ys.index(r[y_axis]), xs.index(r[x_axis])), []).append(r.get(ctx.metric))
        for (i, j), values in cells.items():
            m = _median(values)
            grid[i, j] = np.nan if m is None else m
        title = ", ".join(f"{f} = {_fmt(v)}" for f, v in zip(facets, combo)) or "all runs"
        panels.append((title, grid))
    finite = np.concatenate([g[np.isfinite(g)] for _, g in panels]) if panels else np.array([])
    if finite.size == 0:
        return lines + ["", f"No map: no ok run has a finite `{ctx.metric}`."]
    vmin, vmax = float(finite.min()), float(finite.max())
    log = vmin > 0 and vmax / vmin > 20
    lines += ["", f"Median `{ctx.metric}` over (`{x_axis}`, `{y_axis}`), one panel per {' x '.join(f'`{f}`' for f in facets) or 'study'}; "
              f"one {'logarithmic ' if log else ''}colour scale for all panels ({_fmt(vmin)} to {_fmt(vmax)}), grey: no ok run."]
    for page in range(0, len(panels), MAX_PANELS):
        chunk = panels[page:page + MAX_PANELS]
        name = f"map_{_slug(ctx.metric)}" + (f"_{page // MAX_PANELS + 1}" if len(panels) > MAX_PANELS else "") + ".png"
        last = len(ctx.distinct(facets[-1])) if facets else 1
        _draw_maps(ctx.figures / name, chunk, xs, ys, x_axis, y_axis, ctx.metric, vmin, vmax, last if 1 < last <= 4 else 3)
        lines += ["", f"![map]({ctx.figures.name}/{name})"]
    return lines


def _draw_maps(path: Path, panels, xs, ys, x_axis, y_axis, metric, vmin, vmax, ncols: int) -> None:
    from matplotlib import colormaps
    from matplotlib.figure import Figure

    ncols = min(len(panels), ncols)
    nrows = math.ceil(len(panels) / ncols)
    fig = Figure(figsize=(4.2 * ncols + 1.0, 3.6 * nrows), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
    from matplotlib.colors import LogNorm, Normalize

    cmap = colormaps["viridis"].with_extremes(bad="0.85")
    logarithmic = vmin > 0 and vmax / vmin > 20  # e.g. controllers decades apart: keep each panel's structure visible
    norm = LogNorm(vmin, vmax) if logarithmic else Normalize(vmin, vmax)
    image = None
    for ax, (title, grid) in zip(axes, panels):
        image = ax.imshow(np.ma.masked_invalid(grid), origin="lower", aspect="auto", cmap=cmap, norm=norm)
        step_x, step_y = max(1, len(xs) // 10), max(1, len(ys) // 10)
        ax.set_xticks(range(0, len(xs), step_x), [_fmt(v) for v in xs[::step_x]], fontsize=7)
        ax.set_yticks(range(0, len(ys), step_y), [_fmt(v) for v in ys[::step_y]], fontsize=7)
        ax.set_xlabel(x_axis)
        ax.set_ylabel(y_axis)
        ax.set_title(title, fontsize=9)
        if grid.size <= 64:
            for (i, j), value in np.ndenumerate(grid):
                if np.isfinite(value):
                    light = vmax > vmin and float(norm(value)) > 0.6
                    ax.text(j, i, f"{value:.3g}", ha="center", va="center", fontsize=7, color="k" if light else "w")
    for ax in axes[len(panels):]:
        ax.set_visible(False)
    if image is not None:
        fig.colorbar(image, ax=list(axes[:len(panels)]), label=metric)
    fig.savefig(path, dpi=100)


def _ranking(ctx: _Context) -> list[str]:
    lines = ["## Ranking"]
    rank_by, group_by = ctx.spec.rank_by, ctx.spec.group_by
    if ctx.metric is None or rank_by not in ctx.coords:
        return lines + ["", "No ranking: it needs a metric and a `rank_by` column (a controller axis by default)."]
    groups = ctx.distinct(group_by) if group_by in ctx.coords else [None]
    candidates = ctx.distinct(rank_by)
    sign = 1 if ctx.spec.lower_is_better else -1
    lines += ["", f"Median `{ctx.metric}` of the ok runs per `{rank_by}`" + (f", for each `{group_by}`" if group_by in ctx.coords else "")
              + f"; best first ({'lowest' if sign > 0 else 'highest'})."]
    bars: dict[Any, dict[Any, float]] = {}
    for group in groups:
        members = [r for r in ctx.table.rows if group is None or r.get(group_by) == group]
        entries = []
        for candidate in candidates:
            mine = [r for r in members if r.get(rank_by) == candidate]
            ok = [r.get(ctx.metric) for r in mine if r["status"] == "ok"]
            entries.append((candidate, _median(ok), len(ok), len(mine) - len(ok)))
        entries.sort(key=lambda e: (e[1] is None, sign * e[1] if e[1] is not None else 0.0))
        bars[group] = {c: m for c, m, _, _ in entries if m is not None}
        lines += ["", f"### {group_by} = {_fmt(group)}" if group is not None else "### all runs", ""]
        lines += _md_table(["rank", rank_by, f"median {ctx.metric}", "ok runs", "failed runs"],
                           [(i + 1, c, m, n_ok, n_bad) for i, (c, m, n_ok, n_bad) in enumerate(entries)])
    name = f"ranking_{_slug(ctx.metric)}.png"
    _draw_ranking(ctx.figures / name, bars, candidates, rank_by, group_by, ctx.metric)
    return lines + ["", f"![ranking]({ctx.figures.name}/{name})"]


def _draw_ranking(path: Path, bars, candidates, rank_by, group_by, metric) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(max(5.0, 1.2 * len(bars) * max(1, len(candidates)) * 0.5 + 3), 3.8), layout="constrained")
    ax = fig.subplots()
    width = 0.8 / max(1, len(candidates))
    for k, candidate in enumerate(candidates):
        heights = [bars[g].get(candidate, np.nan) for g in bars]
        ax.bar(np.arange(len(bars)) + (k - (len(candidates) - 1) / 2) * width, heights, width, label=str(candidate))
    ax.set_xticks(range(len(bars)), [f"{group_by} = {_fmt(g)}" if g is not None else "all" for g in bars])
    ax.set_ylabel(f"median {metric}")
    ax.legend(title=rank_by, fontsize=8)
    ax.grid(True, axis="y", alpha=0.3)
    fig.savefig(path, dpi=100)


def _worst(ctx: _Context) -> list[str]:
    lines = ["## Worst cases"]
    if ctx.metric is None or ctx.spec.worst <= 0:
        return lines + ["", "None asked for." if ctx.spec.worst <= 0 else "No metric recorded."]
    rows = [r for r in ctx.ok_rows() if isinstance(r.get(ctx.metric), float)]
    rows.sort(key=lambda r: r[ctx.metric], reverse=ctx.spec.lower_is_better)
    rows = rows[:ctx.spec.worst]
    if not rows:
        return lines + ["", "No ok run yet."]
    lines += ["", f"The {len(rows)} ok runs with the {'largest' if ctx.spec.lower_is_better else 'smallest'} `{ctx.metric}`.", ""]
    lines += _md_table(["rank", "run_id", *ctx.coords, ctx.metric], [(i + 1, r["run_id"], *(r.get(c) for c in ctx.coords), r[ctx.metric]) for i, r in enumerate(rows)])
    for i, row in enumerate(rows):
        arrays = ctx.store.load_trajectories(row["run_id"])
        if not arrays:
            lines += ["", f"Run `{row['run_id']}`: no stored trajectories."]
            continue
        name = f"worst_{i + 1}_{row['run_id']}.png"
        title = f"#{i + 1} {row['run_id']}: " + ", ".join(f"{c} = {_fmt(row.get(c))}" for c in ctx.coords) + f"; {ctx.metric} = {_fmt(row[ctx.metric])}"
        _draw_trajectories(ctx.figures / name, arrays, ctx.spec.signals, ctx.spec.time, title)
        lines += ["", f"![run {row['run_id']}]({ctx.figures.name}/{name})"]
    return lines


def _draw_trajectories(path: Path, arrays: dict[str, np.ndarray], signals, time_name: str, title: str) -> None:
    from matplotlib.figure import Figure

    names = [s for s in (signals or [n for n in arrays if n != time_name]) if s in arrays][:6]
    time = arrays.get(time_name)
    fig = Figure(figsize=(8, 1.9 * max(1, len(names)) + 0.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(max(1, len(names)), 1, sharex=True, squeeze=False)).ravel()
    for ax, name in zip(axes, names):
        y = arrays[name]
        x = time if time is not None and len(time) == len(y) else np.arange(len(y))
        ax.plot(x, y, lw=0.9)
        ax.set_ylabel(name)
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel(f"{time_name} (s)" if time is not None else "sample")
    fig.suptitle(title, fontsize=9)
    fig.savefig(path, dpi=100)


def _timing(ctx: _Context) -> list[str]:
    lines = ["## Timing"]
    timing = [m for m in (ctx.spec.timing or [m for m in ctx.metrics if TIMING.search(m)]) if m in ctx.metrics]
    by = ctx.spec.rank_by if ctx.spec.rank_by in ctx.coords else None
    groups = ctx.distinct(by) if by else [None]
    header = [by or "runs", "ok runs", "median wall time per run (s)", *[f"median {m}" for m in timing]]
    rows = []
    for group in groups:
        ok = [r for r in ctx.ok_rows() if group is None or r.get(by) == group]
        rows.append((group if group is not None else "all", len(ok), _median([r.get("wall_time_s") for r in ok]),
                     *[_median([r.get(m) for r in ok]) for m in timing]))
    lines += ["", "Wall time covers the whole run in its worker (build, design, simulation, metrics); "
              "a worker builds its model once, so its first run is slower.", ""]
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
            rows.append((number, s.get("backend", "?"), ran, s["elapsed_s"], rate, s.get("parent_peak_memory_mb")))
        lines += _md_table(["session", "backend", "runs", "wall time (s)", "runs per minute", "parent peak memory (MB)"], rows) + [""]
    memory = [r.get("peak_memory_mb") for r in ctx.table.rows if isinstance(r.get("peak_memory_mb"), (int, float))]
    disk = [r.get("bytes_written") for r in ctx.table.rows if isinstance(r.get("bytes_written"), (int, float))]
    if memory:
        lines.append(f"- worker peak resident memory when a run ended: median {_fmt(_median(memory))} MB, max {_fmt(max(memory))} MB "
                     "(a worker's high-water mark, so it bounds every run it did)")
    if disk:
        lines.append(f"- disk written per run (record and trajectory): median {_fmt(_median(disk) / 1024)} KiB, "
                     f"max {_fmt(max(disk) / 1024)} KiB, total {_fmt(sum(disk) / 2**20)} MiB over {len(disk)} runs")
    return lines


def _failures(ctx: _Context) -> list[str]:
    lines = ["## Failed runs"]
    failed = [r for r in ctx.table.rows if r["status"] == "failed"]
    if not failed:
        lines += ["", "None."]
    else:
        lines += ["", f"{len(failed)} run(s) failed; the others went on.", ""]
        lines += _md_table(["run_id", *ctx.coords, "error"], [(r["run_id"], *(r.get(c) for c in ctx.coords), (r["error"] or "")[:300]) for r in failed])
    recorded = {r["run_id"] for r in ctx.table.rows}
    pending = [p for p in ctx.store.iter_plan() if p["run_id"] not in recorded]
    if pending:
        lines += ["", f"{len(pending)} run(s) of the grid have no record yet (interrupted study): "
                  "run `flexctrl study STUDY --out DIR --resume` to complete it."]
    return lines
