"""Two ``speed_vs_accuracy`` results side by side: what moved between them.

A study's report writes ``pareto.csv`` (one row per scene and method: median cost,
median and worst tip error, Pareto flag; ``flexctrl.study.executors.speed_vs_accuracy_executor``).
This module reads two of them, e.g. the shipped study and the same study with the
assumed-modes models' axial shortening on (``docs/explanation/speed-and-accuracy.md``), and gives

* :func:`compare`: one row per (scene, method) present in either file, with both sides'
  numbers (missing side: NaN) and whether the method joined or left the Pareto front;
* :func:`markdown`: per scene a table of cost, median and worst error and Pareto flag,
  old and new side by side (errors in mm, cost in s per simulated s);
* :func:`plot`: per scene error against cost on log axes, each method old (hollow) and
  new (filled), joined by an arrow where it moved.

Run ``python -m flexctrl.analysis.pareto_compare --old DIR [DIR ...] --new DIR [DIR ...]
[--labels off on] [--figure PATH]``: prints the tables (and draws the figure).  Several
folders on one side are merged by :func:`merge` (a later folder's scene replaces an
earlier one's, e.g. a scene rerun on its own).
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = [
    "case_table",
    "compare",
    "error_cost_axes",
    "main",
    "markdown",
    "merge",
    "plot",
    "read_pareto",
]

#: Numeric columns of ``pareto.csv`` compared side by side.
#: The scene label of the study report's over-all-scenes group.
ALL_SCENES = "all scenes"
NUMBERS = (
    "wall_per_sim_s",
    "tip_error_rms",
    "tip_error_rms_worst",
    "tip_error_max_worst",
    "runs_ok",
    "runs_failed",
)


def read_pareto(path: str | Path) -> list[dict[str, Any]]:
    """The rows of ``pareto.csv`` (a file or a result folder holding one), numbers as floats,
    ``pareto`` as bool.

    Raises
    ------
    FileNotFoundError
        Naming the file when it is missing (run ``flexctrl report DIR`` to write it).
    """
    path = Path(path)
    if path.is_dir():
        path = path / "pareto.csv"
    if not path.is_file():
        raise FileNotFoundError(
            f"{path}: no pareto.csv (a speed_vs_accuracy study writes it; 'flexctrl report DIR' "
            "redraws it)"
        )
    rows = []
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            row: dict[str, Any] = {
                "scene": r["scene"],
                "method": r["method"],
                "pareto": r["pareto"] == "True",
            }
            for c in NUMBERS:
                row[c] = float(r[c]) if r.get(c) not in (None, "") else math.nan
            rows.append(row)
    return rows


def merge(*tables: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One table from several ``read_pareto`` tables: a scene of a later table replaces that scene's
    rows before it.

    With more than one table the over-all-scenes rows are dropped: they summarise one
    folder's runs and would mix with the replaced scenes.
    """
    rows: list[dict[str, Any]] = []
    for table in tables:
        scenes = {r["scene"] for r in table}
        rows = [r for r in rows if r["scene"] not in scenes] + list(table)
    return [r for r in rows if r["scene"] != ALL_SCENES] if len(tables) > 1 else rows


def compare(old: Sequence[dict[str, Any]], new: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Rows ``{"scene", "method", "old": {...} | None, "new": {...} | None, "front": "joined" |
    "left" | ""}``.

    Order: the old file's, then any (scene, method) only the new one has.
    """
    old_by = {(r["scene"], r["method"]): r for r in old}
    new_by = {(r["scene"], r["method"]): r for r in new}
    keys = list(dict.fromkeys([*old_by, *new_by]))
    out = []
    for key in keys:
        a, b = old_by.get(key), new_by.get(key)
        was, now = bool(a and a["pareto"]), bool(b and b["pareto"])
        out.append(
            {
                "scene": key[0],
                "method": key[1],
                "old": a,
                "new": b,
                "front": "joined" if now and not was else "left" if was and not now else "",
            }
        )
    return out


def _num(row: dict[str, Any] | None, column: str, scale: float = 1.0) -> str:
    if row is None or row["runs_ok"] == 0 or not math.isfinite(row[column]):
        return "-"
    return f"{scale * row[column]:.3g}"


def _flag(row: dict[str, Any] | None) -> str:
    return "-" if row is None else "yes" if row["pareto"] else "no"


def markdown(rows: Sequence[dict[str, Any]], labels: tuple[str, str] = ("old", "new")) -> str:
    """Per scene, a table with both sides' cost, errors, failures and Pareto flag (sorted by the old
    cost)."""
    a, b = labels
    lines: list[str] = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        block = [r for r in rows if r["scene"] == scene]
        block.sort(
            key=lambda r: (
                r["old"] is None or not math.isfinite(r["old"]["wall_per_sim_s"]),
                r["old"]["wall_per_sim_s"] if r["old"] else 0.0,
            )
        )
        lines += [
            f"#### {scene}",
            "",
            f"| method | s per sim. s, {a} / {b} | tip RMS median (mm), {a} / {b} | worst RMS "
            f"(mm), {a} / {b} | "
            f"worst max (mm), {a} / {b} | runs failed, {a} / {b} | Pareto, {a} / {b} |",
            "| --- | --- | --- | --- | --- | --- | --- |",
        ]
        for r in block:
            o, n = r["old"], r["new"]
            moved = f" ({r['front']})" if r["front"] else ""
            lines.append(
                f"| `{r['method']}` | {_num(o, 'wall_per_sim_s')} / {_num(n, 'wall_per_sim_s')} "
                f"| {_num(o, 'tip_error_rms', 1e3)} / {_num(n, 'tip_error_rms', 1e3)} "
                f"| {_num(o, 'tip_error_rms_worst', 1e3)} / {_num(n, 'tip_error_rms_worst', 1e3)} "
                f"| {_num(o, 'tip_error_max_worst', 1e3)} / {_num(n, 'tip_error_max_worst', 1e3)} "
                f"| {'-' if o is None else int(o['runs_failed'])} / "
                f"{'-' if n is None else int(n['runs_failed'])} "
                f"| {_flag(o)} / {_flag(n)}{moved} |"
            )
        lines.append("")
    return "\n".join(lines)


def case_table(
    old: Sequence[str | Path],
    new: Sequence[str | Path],
    scene: str,
    methods: Sequence[str],
    labels: tuple[str, str] = ("old", "new"),
) -> str:
    """Per case (payload, configuration) of ``scene``, each method's tip RMS (mm) on both sides,
    from ``results.csv``.

    The medians of :func:`markdown` can hide a split (e.g. one payload better, the other
    worse); this shows it.  ``old``/``new`` are result folders (later ones win, as in
    :func:`merge`).
    """

    def runs(folders):
        out: dict[tuple, str] = {}
        for folder in folders:
            with open(Path(folder) / "results.csv", newline="") as fh:
                for r in csv.DictReader(fh):
                    if r.get("scene") == scene:
                        value = (
                            f"{1e3 * float(r['tip_error_rms']):.3g}"
                            if r.get("status") == "ok"
                            else r.get("status", "-")
                        )
                        out[
                            (r["payload"], r.get("q1"), r.get("q2"), r.get("q3"), r["scene.method"])
                        ] = value
        return out

    a, b = runs(old), runs(new)
    cases = list(dict.fromkeys(k[:4] for k in [*a, *b]))
    head = (
        "| payload (kg) | q1, q2, q3 (deg) | "
        + " | ".join(f"`{m}` {labels[0]} / {labels[1]}" for m in methods)
        + " |"
    )
    lines = [head, "| --- | --- |" + " --- |" * len(methods)]
    for case in cases:
        cells = [f"{a.get((*case, m), '-')} / {b.get((*case, m), '-')}" for m in methods]
        angles = ", ".join(f"{float(q):g}" for q in case[1:] if q not in (None, ""))
        lines.append(f"| {float(case[0]):g} | {angles} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def error_cost_axes(ax, title: str) -> None:
    """Log axes of tip error RMS (mm) against integration wall time per simulated second (s/s):
    every Pareto chart's."""
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time per simulated second (s/s), median")
    ax.set_ylabel("tip error RMS (mm), median over cases")
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.25)


def plot(
    rows: Sequence[dict[str, Any]],
    path: str | Path,
    labels: tuple[str, str] = ("old", "new"),
    title: str = "",
    dpi: int = 90,
) -> Path:
    """Per scene, median tip error RMS (mm) against median cost (s/s), old hollow, new filled, an
    arrow where it moved."""
    from matplotlib.figure import Figure

    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    ncols = min(2, len(scenes))
    nrows = math.ceil(len(scenes) / ncols)
    fig = Figure(figsize=(7.0 * ncols, 5.4 * nrows), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    colours = {"rigid": "tab:gray", "amm": "tab:blue", "fem": "tab:red"}

    def point(row):
        if (
            row is None
            or row["runs_failed"] > 0
            or not (math.isfinite(row["wall_per_sim_s"]) and math.isfinite(row["tip_error_rms"]))
        ):
            return None
        return row["wall_per_sim_s"], 1e3 * max(row["tip_error_rms"], 1e-12)

    for ax, scene in zip(axes, scenes):
        for r in (r for r in rows if r["scene"] == scene):
            colour = colours.get(r["method"].split(":")[0].split("/")[0], "k")
            p, q = point(r["old"]), point(r["new"])
            if p:
                ax.scatter(
                    *p,
                    facecolors="none",
                    edgecolors=colour,
                    s=60 if r["old"]["pareto"] else 26,
                    lw=1.6 if r["old"]["pareto"] else 0.9,
                    zorder=3,
                )
            if q:
                ax.scatter(
                    *q,
                    c=colour,
                    s=60 if r["new"]["pareto"] else 26,
                    edgecolors="k" if r["new"]["pareto"] else "none",
                    zorder=4,
                )
            if p and q and (abs(math.log(q[1] / p[1])) > 0.05):
                ax.annotate(
                    "", q, p, arrowprops={"arrowstyle": "->", "color": colour, "lw": 0.8}, zorder=2
                )
            if p or q:
                ax.annotate(
                    r["method"], q or p, fontsize=6, xytext=(3, 3), textcoords="offset points"
                )
        for side, face in ((labels[0], "none"), (labels[1], "0.5")):
            ax.scatter([], [], facecolors=face, edgecolors="0.5", s=26, label=side)
        for family, colour in colours.items():
            ax.scatter([], [], c=colour, s=26, label=family)
        ax.scatter(
            [], [], facecolors="none", edgecolors="k", s=60, lw=1.6, label="large: Pareto-optimal"
        )
        ax.legend(fontsize=7, loc="lower left", ncol=2)
        error_cost_axes(ax, scene)
    for ax in axes[len(scenes) :]:
        ax.set_visible(False)
    fig.suptitle(
        title
        or f"speed against accuracy: {labels[0]} (hollow) and {labels[1]} (filled); methods with "
        "failed runs left out",
        fontsize=9,
    )
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    path = Path(path)
    fig.savefig(path, dpi=dpi)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--old",
        nargs="+",
        required=True,
        metavar="DIR",
        help="result folders (or pareto.csv) of the first side",
    )
    parser.add_argument(
        "--new",
        nargs="+",
        required=True,
        metavar="DIR",
        help="result folders (or pareto.csv) of the second side",
    )
    parser.add_argument("--labels", nargs=2, default=("old", "new"), metavar=("OLD", "NEW"))
    parser.add_argument("--figure", help="also draw error against cost to this PNG")
    parser.add_argument(
        "--cases",
        nargs="+",
        metavar=("SCENE", "METHOD"),
        help="instead: per case tip RMS (mm) of these methods in SCENE, from results.csv",
    )
    args = parser.parse_args(argv)
    if args.cases:
        print(case_table(args.old, args.new, args.cases[0], args.cases[1:], tuple(args.labels)))
        return 0
    try:
        rows = compare(merge(*map(read_pareto, args.old)), merge(*map(read_pareto, args.new)))
    except FileNotFoundError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(markdown(rows, tuple(args.labels)))
    if args.figure:
        print(f"figure: {plot(rows, args.figure, tuple(args.labels))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
