"""The study report's timing section: wall time per run, computing-time metrics, resources."""

from __future__ import annotations

import math
import re
import statistics

from flexctrl.study.column_units import display
from flexctrl.study.report_context import ReportContext, fmt, md_table, median

TIMING = re.compile(r"(controller|solve|solver|step|compute|cpu|qp|nlp)_?time", re.IGNORECASE)


def timing_section(ctx: ReportContext) -> list[str]:
    """``## Timing``: per ``rank_by`` value, the median wall time and computing-time metrics."""
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
                median([r.get("wall_time_s") for r in ok]),
                *[display(m).value(median([r.get(m) for r in ok])) for m in timing],
            )
        )
    lines += [
        "",
        "Wall time covers the whole run in its worker (build, design, simulation, metrics); "
        "a worker builds its model once, so its first run is slower.",
        "",
    ]
    return lines + md_table(header, rows) + ["", *_resources(ctx)]


def _resources(ctx: ReportContext) -> list[str]:
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
        lines += md_table(
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
    memory = _numbers(ctx, "peak_memory_mb")
    disk = _numbers(ctx, "bytes_written")
    if memory:
        lines.append(
            f"- worker peak resident memory when a run ended: median {fmt(median(memory))} MB, "
            f"max {fmt(max(memory))} MB "
            "(a worker's high-water mark, so it bounds every run it did)"
        )
    if disk:
        lines.append(
            "- disk written per run (record and trajectory): median "
            f"{fmt(statistics.median(disk) / 1024)} KiB, "
            f"max {fmt(max(disk) / 1024)} KiB, total {fmt(sum(disk) / 2**20)} MiB over "
            f"{len(disk)} runs"
        )
    return lines


def _numbers(ctx: ReportContext, column: str) -> list[float]:
    """The finite numbers of one column."""
    values = (r.get(column) for r in ctx.table.rows)
    return [float(v) for v in values if isinstance(v, (int, float)) and math.isfinite(v)]
