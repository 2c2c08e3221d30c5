"""The study report's maps: the metric over two grid columns, the best per cell and every
value's ratio to it."""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from flexctrl.study.column_units import display, with_unit
from flexctrl.study.report_context import ReportContext, cell_medians, facet_title, fmt, slug
from flexctrl.study.report_figures import (
    TEXT_CELLS,
    draw_best_map,
    draw_value_maps,
    wants_log,
)

MAX_PANELS = 12


def _map_axes(ctx: ReportContext) -> tuple[str, str] | None:
    if ctx.spec.map_axes:
        return tuple(ctx.spec.map_axes)  # type: ignore[return-value]
    varying = [c for c in ctx.coords if c != "replicate" and len(ctx.distinct(c)) > 1]
    if "q2" in varying and "q3" in varying:
        return ("q2", "q3")
    numeric = [c for c in varying if all(isinstance(v, float) for v in ctx.distinct(c))]
    return (numeric[0], numeric[1]) if len(numeric) >= 2 else None


def map_section(ctx: ReportContext) -> list[str]:
    """The ``maps`` section: the metric over the map axes, then the best per cell."""
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
    rows = ctx.ranked_rows()
    xs, ys = ctx.distinct(x_axis), ctx.distinct(y_axis)
    shown = display(ctx.metric)
    panels = []
    for combo in itertools.product(*(ctx.distinct(f) for f in facets)):
        members = [r for r in rows if all(r.get(f) == v for f, v in zip(facets, combo))]
        panels.append(
            (
                facet_title(facets, combo),
                shown.scale * cell_medians(ctx, members, xs, ys, x_axis, y_axis),
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
        f"panels ({fmt(float(finite.min()))} to "
        f"{fmt(float(finite.max()))}{' ' + shown.unit if shown.unit else ''}), grey: no ok run.",
    ]
    last = len(ctx.distinct(facets[-1])) if facets else 1
    for page in range(0, len(panels), MAX_PANELS):
        name = (
            f"map_{slug(ctx.metric)}"
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


def _best_and_ratio_panels(ctx, others, candidates, xs, ys, x_axis, y_axis, sign: float):
    """Per combination of the other facets: the best candidate(s) and value of every cell, each
    candidate's ratio to the cell's best, and whether the metric only takes 0 and 1."""
    rank_by = ctx.spec.rank_by
    shown = display(ctx.metric)
    best_panels, ratio_panels, binary = [], [], True
    for combo in itertools.product(*(ctx.distinct(f) for f in others)):
        members = [
            r for r in ctx.ranked_rows() if all(r.get(f) == v for f, v in zip(others, combo))
        ]
        grids = {
            c: cell_medians(
                ctx, [r for r in members if r.get(rank_by) == c], xs, ys, x_axis, y_axis
            )
            for c in candidates
        }
        stack = np.stack([grids[c] for c in candidates])
        binary &= bool(np.all(np.isin(stack[np.isfinite(stack)], (0.0, 1.0))))
        cells: list[list[Any]] = [[None] * len(xs) for _ in ys]
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
        title = facet_title(others, combo)
        best_panels.append((title, cells))
        with np.errstate(divide="ignore", invalid="ignore"):
            for c in candidates:
                ratio = grids[c] / best if sign > 0 else best / grids[c]
                ratio_panels.append(
                    (f"{with_unit(rank_by, c)}" + (f"; {title}" if others else ""), ratio)
                )
    return best_panels, ratio_panels, binary


def _best_maps(
    ctx: ReportContext, facets: list[str], xs, ys, x_axis: str, y_axis: str
) -> list[str]:
    """Which ``rank_by`` value is best in each cell, and every value's ratio to that best."""
    rank_by, metric = ctx.spec.rank_by, ctx.metric
    if metric is None or rank_by is None or rank_by not in ctx.coords:
        return []
    candidates = ctx.distinct(rank_by)
    if len(candidates) < 2 or rank_by in (x_axis, y_axis):
        return []
    others = [f for f in facets if f != rank_by]
    shown = display(metric)
    sign = 1.0 if ctx.lower_is_better else -1.0
    best_panels, ratio_panels, binary = _best_and_ratio_panels(
        ctx, others, candidates, xs, ys, x_axis, y_axis, sign
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
    name = f"best_{slug(metric)}.png"
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
            f"No ratio map: `{metric}` takes only the values 0 and 1, so the best map says it all."
            if binary
            else "No ratio map: no finite ratio.",
        ]
    name = f"ratio_{slug(metric)}.png"
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
