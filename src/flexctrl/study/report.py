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
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.errors import SpecError, keyword_checked
from flexctrl.study.column_units import display, lower_is_better, metric_info, with_unit
from flexctrl.study.plan import ReportSpec
from flexctrl.study.report_context import (
    ReportContext,
    columns,
    diverged,
    fmt,
    md_table,
    median,
    slug,
)
from flexctrl.study.report_diverged import diverged_section
from flexctrl.study.report_figures import (
    draw_ranking,
    draw_signals,
)
from flexctrl.study.report_maps import map_section
from flexctrl.study.report_timing import timing_section
from flexctrl.study.store import ResultStore, atomic_write


@keyword_checked
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
    coords, metrics = columns(table)
    asked = spec.metric, spec.lower_is_better
    if metric is not None:
        if metric not in metrics:
            raise SpecError(
                f"'{metric}' is not a metric of this study; allowed: "
                f"{', '.join(metrics) or '(none recorded)'}",
                key="--metric",
            )
        spec = dataclasses.replace(spec, metric=metric)
    if map_axes is not None:
        if len(map_axes) != 2:
            raise SpecError(
                f"{list(map_axes)} names {len(map_axes)} columns; allowed: two grid columns "
                f"of {', '.join(coords)}",
                key="--map-axes",
            )
        for axis in map_axes:
            if axis not in coords:
                raise SpecError(
                    f"'{axis}' is not a grid column; allowed: {', '.join(coords)}", key="--map-axes"
                )
        spec = dataclasses.replace(spec, map_axes=(map_axes[0], map_axes[1]))
    if worst is not None:
        spec = dataclasses.replace(spec, worst=worst)
    chosen = spec.metric if spec.metric in metrics else (metrics[0] if metrics else None)
    if chosen is not None and (asked[1] is None or chosen != asked[0]):
        spec = dataclasses.replace(spec, lower_is_better=lower_is_better(chosen))
    figures = store.dir / "figures"
    figures.mkdir(exist_ok=True)
    for old in figures.glob("*.png"):
        old.unlink()
    ctx = ReportContext(store, table, study, spec, coords, metrics, chosen, figures)

    lines = _header(ctx)
    sections = {
        "maps": map_section,
        "ranking": _ranking,
        "worst": _worst,
        "timing": timing_section,
        "failures": _failures,
    }
    for name in spec.plots:
        lines += ["", *sections[name](ctx)]
    if "failures" not in spec.plots:
        lines += ["", *_failures(ctx)]
    lines += _warnings(ctx)
    lines += ["", *diverged_section(ctx)]
    lines += _executor_sections(ctx)
    path = store.dir / "report.md"
    atomic_write(path, ("\n".join(lines) + "\n").encode())
    return path


def _executor_sections(ctx: ReportContext) -> list[str]:
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


def _header(ctx: ReportContext) -> list[str]:
    s = ctx.study.get("study", {})
    statuses = [row["status"] for row in ctx.table.rows]
    n_plan = s.get("n_runs", len(statuses))
    ok, failed = statuses.count("ok"), statuses.count("failed")
    diverged = len(ctx.diverged_rows())
    versions = ctx.study.get("versions", {})
    machine = ctx.study.get("machine", {})
    lines = [
        f"# Study `{s.get('name', '?')}`",
        "",
        f"- study file: `{s.get('source', '?')}` (sha256 {s.get('sha256', '?')}), executor "
        f"`{s.get('executor', '?')}`, seed {s.get('seed', '?')}",
        f"- runs: {n_plan} in the grid; {ok} ok"
        + (f" ({diverged} of them diverged, listed apart)" if diverged else "")
        + f", {failed} failed, {max(n_plan - ok - failed, 0)} not run",
        "- grid: "
        + (", ".join(f"{k} ({len(v)})" for k, v in s.get("grid", {}).items()) or "a single run"),
        f"- report metric: `{ctx.metric}` ({'lower' if ctx.lower_is_better else 'higher'} "
        "is better)"
        if ctx.metric
        else "- no metric recorded yet",
        f"- started {ctx.study.get('start', '?')}, ended "
        f"{ctx.study.get('end') or 'not yet (interrupted or running)'}; "
        f"{len(ctx.study.get('sessions', []))} session(s), last on "
        f"{ctx.study.get('sessions', [{}])[-1].get('backend', '?')}",
        f"- machine: {machine.get('platform', '?')}, {machine.get('cpu_count', '?')} CPUs",
        "- versions: " + ", ".join(f"{k} {v}" for k, v in versions.items()),
        "",
        "Files: `results.csv` (one row per run), `runs/<id>.json` (records), `runs/<id>.npz` "
        "(trajectories), `study.json`.",
    ]
    return lines


def _ranking(ctx: ReportContext) -> list[str]:
    lines = ["## Ranking"]
    metric, rank_by = ctx.metric, ctx.spec.rank_by
    group_by = ctx.spec.group_by if ctx.spec.group_by in ctx.coords else None
    if metric is None or rank_by is None or rank_by not in ctx.coords:
        return lines + [
            "",
            "No ranking: it needs a metric and a `rank_by` column (a controller axis by default).",
        ]
    groups = ctx.distinct(group_by) if group_by is not None else [None]
    candidates = ctx.distinct(rank_by)
    sign = 1 if ctx.lower_is_better else -1
    shown = display(metric)
    lines += [
        "",
        f"Median {shown.label} of the {_compared(ctx)} per `{rank_by}`"
        + (f", for each `{group_by}`" if group_by in ctx.coords else "")
        + f"; best first ({'lowest' if sign > 0 else 'highest'}); min and max over the other "
        "grid columns (poses ...).",
    ]
    values: dict[Any, dict[Any, list[float]]] = {}
    ranked = {id(r) for r in ctx.ranked_rows()}
    for group in groups:
        members = [r for r in ctx.table.rows if group_by is None or r.get(group_by) == group]
        entries = []
        values[group] = {}
        for candidate in candidates:
            mine = [r for r in members if r.get(rank_by) == candidate]
            ok = [
                shown.value(r.get(metric))
                for r in mine
                if id(r) in ranked and isinstance(r.get(metric), float)
            ]
            values[group][candidate] = ok
            entries.append(
                (
                    candidate,
                    median(ok),
                    min(ok, default=None),
                    max(ok, default=None),
                    len(ok),
                    sum(1 for r in mine if r["status"] == "ok" and diverged(r)),
                    sum(1 for r in mine if r["status"] != "ok"),
                )
            )
        entries.sort(key=lambda e: (e[1] is None, sign * e[1] if e[1] is not None else 0.0))
        u = f" ({shown.unit})" if shown.unit else ""
        lines += [
            "",
            f"### {with_unit(group_by, group)}" if group_by is not None else "### all runs",
            "",
        ]
        lines += md_table(
            [
                "rank",
                rank_by,
                f"median {shown.label}",
                f"min{u}",
                f"max{u}",
                "runs ranked",
                "diverged runs",
                "failed runs",
            ],
            [(i + 1, *entry) for i, entry in enumerate(entries)],
        )
    name = f"ranking_{slug(metric)}.png"
    draw_ranking(ctx.figures / name, values, candidates, rank_by, group_by, shown)
    return lines + ["", f"![ranking]({ctx.figures.name}/{name})"]


def _worst(ctx: ReportContext) -> list[str]:
    lines = ["## Worst cases"]
    if ctx.metric is None or ctx.spec.worst <= 0:
        return lines + ["", "None asked for." if ctx.spec.worst <= 0 else "No metric recorded."]
    rows = [r for r in ctx.ranked_rows() if isinstance(r.get(ctx.metric), float)]
    rows.sort(key=lambda r: r[ctx.metric], reverse=ctx.lower_is_better)
    rank_by = ctx.spec.rank_by if ctx.spec.rank_by in ctx.coords else None
    rows = _one_per_cell(rows, [c for c in ctx.coords if c != rank_by])[: ctx.spec.worst]
    if not rows:
        return lines + ["", "No ok run yet."]
    shown = display(ctx.metric)
    lines += [
        "",
        f"The {len(rows)} {_compared(ctx)} with the "
        f"{'largest' if ctx.lower_is_better else 'smallest'} {shown.label}"
        + (
            f", each drawn with every `{rank_by}` of its cell on the same axes (the worst one "
            "thicker)."
            if rank_by
            else "."
        ),
        "",
    ]
    lines += md_table(
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
            + f"; worst: {label(row)}, {shown.label} = {fmt(shown.value(row[ctx.metric]))}"
        )
        _draw_cell(ctx, ctx.figures / name, stored, label, title, label(row))
        lines += ["", f"![run {row['run_id']}]({ctx.figures.name}/{name})"]
    return lines


def _compared(ctx: ReportContext) -> str:
    """What the ranked rows are, in words."""
    info = None if ctx.metric is None else metric_info(ctx.metric)
    return "ok runs" if info is not None and info.verdict else "ok runs that did not diverge"


def _one_per_cell(rows: list[dict], cell: Sequence[str]) -> list[dict]:
    """``rows`` in order, keeping the first of each cell (equal values of ``cell``): a worst
    case's figure draws its whole cell, so a second run of the same cell would repeat it."""
    seen, out = set(), []
    for row in rows:
        key = tuple(repr(row.get(c)) for c in cell)
        if key not in seen:
            seen.add(key)
            out.append(row)
    return out


def _draw_cell(ctx: ReportContext, path: Path, stored, label, title: str, highlight: str) -> None:
    """The closed loop's four panels (:func:`flexctrl.loop.compare_figure.draw_runs`) or any
    executor's signals."""
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


def _run_curves(ctx: ReportContext, row: dict, arrays: dict[str, np.ndarray], label: str):
    """A closed-loop run's stored trajectories (``t``, ``e``, ``q<k>``, ``u<k>``, ``w<k>``) as
    curves."""
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


def _failures(ctx: ReportContext) -> list[str]:
    lines = ["## Failed runs"]
    failed = [r for r in ctx.table.rows if r["status"] == "failed"]
    if not failed:
        lines += ["", "None."]
    else:
        lines += ["", f"{len(failed)} run(s) failed; the others went on.", ""]
        lines += md_table(
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


def _warnings(ctx: ReportContext) -> list[str]:
    """A section listing each distinct warning the runs raised, with its count (none: empty)."""
    seen: dict[str, list] = {}
    for row in ctx.table.rows:
        record = ctx.store.read_record(row["run_id"]) or {}
        for line in record.get("warnings") or ():
            seen.setdefault(line, []).append(row)
    if not seen:
        return []
    lines = [
        "",
        "## Warnings",
        "",
        "What the runs warned of (each warning once, with its runs):",
        "",
    ]
    rows = [
        (len(runs), runs[0]["run_id"], ", ".join(f"{c}={runs[0].get(c)}" for c in ctx.coords), line)
        for line, runs in seen.items()
    ]
    return lines + md_table(["runs", "first run", "its coordinates", "warning"], rows)
