"""The study report's figures: metric maps, best-per-cell and ratio maps, ranking, worst cases.

Every number is drawn in the unit a reader expects (:mod:`flexctrl.study.column_units`); a
colour scale or value axis is logarithmic when its values span more than
:data:`LOG_SPAN` (a 0.008 mm bar beside 1 mm ones stays visible).  Plain matplotlib
``Figure`` objects (no pyplot state), saved at 100 dpi.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.study.column_units import Shown, display

#: Ratio of the largest to the smallest positive value above which a scale is logarithmic.
LOG_SPAN = 20.0


# : Cells per panel up to which a map writes its values (names, for the best map) into the cells; a
# 12 x 12 grid
#: of the sweep at 100 dpi leaves about 20 pixels per cell, where the text of neighbours overlaps.
TEXT_CELLS = 64


def _fmt_cell(value: float) -> str:
    return f"{value:.3g}"


def wants_log(values: np.ndarray) -> bool:
    """Positive values spanning more than :data:`LOG_SPAN`."""
    finite = values[np.isfinite(values)]
    return (
        bool(finite.size)
        and float(finite.min()) > 0
        and float(finite.max()) / float(finite.min()) > LOG_SPAN
    )


def _ticks(ax, xs, ys, x: Shown, y: Shown) -> None:
    step_x, step_y = max(1, len(xs) // 10), max(1, len(ys) // 10)
    ax.set_xticks(
        range(0, len(xs), step_x),
        [f"{x.value(v):g}" if isinstance(v, float) else str(v) for v in xs[::step_x]],
        fontsize=7,
    )
    ax.set_yticks(
        range(0, len(ys), step_y),
        [f"{y.value(v):g}" if isinstance(v, float) else str(v) for v in ys[::step_y]],
        fontsize=7,
    )
    ax.set_xlabel(x.label)
    ax.set_ylabel(y.label)


def _panel_grid(n: int, ncols: int, size: tuple[float, float]):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ncols = max(1, min(n, ncols))
    nrows = math.ceil(n / ncols)
    fig = Figure(figsize=(size[0] * ncols + 1.2, size[1] * nrows + 0.4), layout="constrained")
    FigureCanvasAgg(fig)
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
    for ax in axes[n:]:
        ax.set_visible(False)
    return fig, axes[:n]


def draw_value_maps(
    path: Path,
    panels: Sequence[tuple[str, np.ndarray]],
    xs,
    ys,
    x_axis: str,
    y_axis: str,
    colour_label: str,
    ncols: int,
    *,
    ratio: bool = False,
) -> None:
    """Heat maps of shown values (already in display units), one colour scale for all panels.

    ``ratio``: the panels hold ratios to the best (>= 1), written ``x1.5``, on a colour
    scale from 1.
    """
    from matplotlib import colormaps
    from matplotlib.colors import BoundaryNorm, ListedColormap, LogNorm, Normalize

    finite = np.concatenate([g[np.isfinite(g)].ravel() for _, g in panels])
    vmin, vmax = (
        (1.0, max(float(finite.max()), 1.0 + 1e-9))
        if ratio
        else (float(finite.min()), float(finite.max()))
    )
    binary = not ratio and bool(np.all(np.isin(finite, (0.0, 1.0))))
    if binary:  # a 0/1 verdict: two colours, not a continuous scale
        cmap = ListedColormap(["#d95f02", "#1f78b4"]).with_extremes(
            bad="0.85"
        )  # orange 0, blue 1: safe for red-green blindness
        norm: Normalize = BoundaryNorm([-0.5, 0.5, 1.5], 2)
    else:
        norm = (
            LogNorm(vmin, vmax)
            if wants_log(np.array([vmin, vmax]))
            else Normalize(vmin, vmax if vmax > vmin else vmin + 1)
        )
        cmap = colormaps["magma_r" if ratio else "viridis"].with_extremes(bad="0.85")
    fig, axes = _panel_grid(len(panels), ncols, (3.6, 3.0))
    image = None
    for ax, (title, grid) in zip(axes, panels):
        image = ax.imshow(
            np.ma.masked_invalid(grid), origin="lower", aspect="auto", cmap=cmap, norm=norm
        )
        _ticks(ax, xs, ys, display(x_axis), display(y_axis))
        ax.set_title(title, fontsize=8)
        if grid.size <= TEXT_CELLS:
            for (i, j), value in np.ndenumerate(grid):
                if np.isfinite(value):
                    dark = binary or (
                        float(norm(value)) > 0.6 if ratio else float(norm(value)) < 0.6
                    )
                    ax.text(
                        j,
                        i,
                        ("×" if ratio else "") + _fmt_cell(value),
                        ha="center",
                        va="center",
                        fontsize=7,
                        color="w" if dark else "k",
                    )
    bar = fig.colorbar(image, ax=list(axes), label=colour_label, shrink=0.9)
    if binary:
        bar.set_ticks([0, 1])
    fig.savefig(path, dpi=100)


def draw_best_map(
    path: Path,
    panels: Sequence[tuple[str, list[list[Any]]]],
    candidates: Sequence[Any],
    xs,
    ys,
    x_axis: str,
    y_axis: str,
    metric: Shown,
    ncols: int,
) -> None:
    """Per cell, the best candidate's colour with its name and value; ties hatched with every name.

    ``panels``: (title, cells) with ``cells[i][j]`` None (no ok run) or (winners, shown value).
    Grids of more than :data:`TEXT_CELLS` cells get the colours and hatching alone.
    """
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch, Rectangle

    colours = _colours(len(candidates))
    cmap = ListedColormap(colours).with_extremes(bad="0.85")
    fig, axes = _panel_grid(len(panels), ncols, (3.8, 3.0))
    for ax, (title, cells) in zip(axes, panels):
        index = np.full((len(ys), len(xs)), np.nan)
        for i, row in enumerate(cells):
            for j, cell in enumerate(row):
                if cell is None:
                    continue
                winners, value = cell
                if len(winners) == 1:
                    index[i, j] = candidates.index(winners[0])
                else:
                    ax.add_patch(
                        Rectangle(
                            (j - 0.5, i - 0.5),
                            1,
                            1,
                            facecolor="0.97",
                            edgecolor="0.6",
                            hatch="//",
                            lw=0,
                        )
                    )
                if len(xs) * len(ys) > TEXT_CELLS:
                    continue
                names = (
                    "\n".join(map(str, winners))
                    if len(winners) <= 3
                    else f"{len(winners)} tied:\n" + "\n".join(map(str, winners[:2])) + "\n..."
                )
                ax.text(
                    j,
                    i,
                    f"{names}\n{_fmt_cell(value)}",
                    ha="center",
                    va="center",
                    fontsize=6.5,
                    color="k" if len(winners) > 1 else "w",
                )
        ax.imshow(
            np.ma.masked_invalid(index),
            origin="lower",
            aspect="auto",
            cmap=cmap,
            vmin=-0.5,
            vmax=len(candidates) - 0.5,
            interpolation="nearest",
        )
        _ticks(ax, xs, ys, display(x_axis), display(y_axis))
        ax.set_xlim(-0.5, len(xs) - 0.5)
        ax.set_ylim(-0.5, len(ys) - 0.5)
        ax.set_title(title, fontsize=8)
    handles = [Patch(color=c, label=str(name)) for c, name in zip(colours, candidates)]
    tie = "tie (names listed)" if len(xs) * len(ys) <= TEXT_CELLS else "tie"
    handles.append(Patch(facecolor="0.97", edgecolor="0.6", hatch="//", label=tie))
    fig.legend(
        handles=handles,
        loc="outside right center",
        fontsize=7,
        title=f"best by\n{metric.label}",
        title_fontsize=7,
    )
    fig.savefig(path, dpi=100)


def _group_label(group_by: str | None, group: Any) -> str:
    """A ranking group as a reader reads it: ``"payload = 2 kg"``, or "all runs"."""
    from flexctrl.study.column_units import with_unit

    return "all runs" if group_by is None or group is None else with_unit(group_by, group)


def draw_ranking(
    path: Path,
    groups: dict[Any, dict[Any, list[float]]],
    candidates: Sequence[Any],
    rank_by: str,
    group_by: str | None,
    metric: Shown,
) -> None:
    """Bars of the median per candidate and group, with every ok run as a dot (the spread over
    poses)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(
        figsize=(max(5.5, 0.45 * len(groups) * max(1, len(candidates)) + 3.0), 4.0),
        layout="constrained",
    )
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    width = 0.8 / max(1, len(candidates))
    every = np.array(
        [v for values in groups.values() for vs in values.values() for v in vs], dtype=float
    )
    log = wants_log(every)
    rng = np.random.default_rng(0)  # the dots' sideways jitter only
    colours = _colours(len(candidates))
    all_centres = []
    for k, candidate in enumerate(candidates):
        centres = np.arange(len(groups)) + (k - (len(candidates) - 1) / 2) * width
        all_centres.append(centres)
        medians = [
            float(np.median(groups[g][candidate])) if groups[g].get(candidate) else np.nan
            for g in groups
        ]
        ax.bar(centres, medians, width * 0.92, color=colours[k], alpha=0.6, label=str(candidate))
        for centre, group in zip(centres, groups):
            values = np.asarray(groups[group].get(candidate, []), dtype=float)
            if values.size:
                ax.plot(
                    centre + rng.uniform(-0.25, 0.25, values.size) * width,
                    values,
                    ".",
                    color=colours[k],
                    ms=3.5,
                    mec="k",
                    mew=0.3,
                )
    if log:
        ax.set_yscale("log")
    if len(groups) == 1:  # one group: name every bar under it
        ax.set_xticks(
            [c[0] for c in all_centres],
            [str(c) for c in candidates],
            rotation=30,
            ha="right",
            fontsize=8,
        )
        only = next(iter(groups))
        ax.set_xlabel(_group_label(group_by, only))
    else:
        ax.set_xticks(
            range(len(groups)),
            [_group_label(group_by, g) for g in groups],
        )
    ax.set_ylabel(metric.label + (", log scale" if log else ""))
    ax.set_title(
        "bars: median over the ok runs\ndots: every ok run (the spread over the other grid "
        "columns)",
        fontsize=8,
    )
    if len(groups) > 1:
        fig.legend(title=rank_by, fontsize=7, title_fontsize=7, loc="outside right upper")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    fig.savefig(path, dpi=100)


def _colours(n: int) -> list:
    """``n`` distinct colours: the default cycle up to 10, tab20 beyond (no colour used twice)."""
    from matplotlib import colormaps

    return (
        [f"C{k}" for k in range(n)] if n <= 10 else [colormaps["tab20"](k % 20) for k in range(n)]
    )


def draw_signals(
    path: Path,
    runs: Sequence[tuple[str, dict[str, np.ndarray]]],
    signals: Sequence[str] | None,
    time_name: str,
    title: str,
    highlight: str | None = None,
) -> None:
    """Any executor's stored signals, one panel per signal, every run of the cell on the same
    axes."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    first = runs[0][1]
    names = [s for s in (signals or [n for n in first if n != time_name]) if s in first][:6]
    fig = Figure(figsize=(8, 1.9 * max(1, len(names)) + 0.6), layout="constrained")
    FigureCanvasAgg(fig)
    axes = np.atleast_1d(fig.subplots(max(1, len(names)), 1, sharex=True, squeeze=False)).ravel()
    for k, (label, arrays) in enumerate(runs):
        time = arrays.get(time_name)
        for ax, name in zip(axes, names):
            if name not in arrays:
                continue
            shown = display(name, trajectory=True)
            y = shown.scale * np.asarray(arrays[name], dtype=float)
            x = time if time is not None and len(time) == len(y) else np.arange(len(y))
            ax.plot(x, y, lw=1.8 if label == highlight else 0.9, color=f"C{k % 10}", label=label)
            ax.set_ylabel(shown.label)
    for ax in axes:
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=7)
    axes[-1].set_xlabel(f"{time_name} (s)" if time_name in first else "sample")
    fig.suptitle(title, fontsize=9)
    fig.savefig(path, dpi=100)
