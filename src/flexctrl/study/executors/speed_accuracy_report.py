"""The ``speed_vs_accuracy`` study's report: per method the error against the cost, the Pareto
front, and the reference's convergence.
"""

from __future__ import annotations

import csv
import math
import statistics
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.analysis.accuracy import pareto_front
from flexctrl.analysis.simulation_methods import parse_method
from flexctrl.errors import SpecError

#: Scene keys read by this executor (removed before the scene file is validated).

# -- the report ------------------------------------------------------------------------------

METHOD_COLUMN = "scene.method"
ALL = "all scenes"


def _median(values) -> float:
    values = [v for v in values if isinstance(v, float) and math.isfinite(v)]
    return statistics.median(values) if values else math.nan


def summarise(rows: list[dict]) -> list[dict[str, Any]]:
    """Per (scene, method) and per method over all scenes: medians, worst cases and the Pareto flag.

    ``cost`` is the median ``wall_per_sim_s``, ``error`` the median ``tip_error_rms``
    (m) over the ok runs of the group; a method with a failed run in a group keeps its
    ok runs' numbers and is listed with the failure count.
    """
    methods = list(dict.fromkeys(r.get(METHOD_COLUMN) for r in rows if r.get(METHOD_COLUMN)))
    scenes = list(dict.fromkeys(str(r.get("scene")) for r in rows if r.get("scene") is not None))
    groups = [(s, [r for r in rows if str(r.get("scene")) == s]) for s in scenes]
    if len(scenes) != 1:
        groups.append((ALL, rows))
    out: list[dict[str, Any]] = []
    for scene, members in groups:
        block: list[dict[str, Any]] = []
        for label in methods:
            mine = [r for r in members if r.get(METHOD_COLUMN) == label]
            ok = [r for r in mine if r.get("status") == "ok"]
            if not mine:
                continue
            try:
                m = parse_method(label)
                model, integ = m.model_label, m.integrator_label
            except SpecError:
                model, integ = str(label), ""
            block.append(
                {
                    "scene": scene,
                    "method": label,
                    "model": model,
                    "integrator": integ,
                    "runs_ok": len(ok),
                    "runs_failed": len(mine) - len(ok),
                    "wall_per_sim_s": _median([r.get("wall_per_sim_s") for r in ok]),
                    "tip_error_rms": _median([r.get("tip_error_rms") for r in ok]),
                    "tip_error_rms_worst": max(
                        [
                            r["tip_error_rms"]
                            for r in ok
                            if isinstance(r.get("tip_error_rms"), float)
                        ],
                        default=math.nan,
                    ),
                    "tip_error_max_worst": max(
                        [
                            r["tip_error_max"]
                            for r in ok
                            if isinstance(r.get("tip_error_max"), float)
                        ],
                        default=math.nan,
                    ),
                    "n_states": _median([r.get("n_states") for r in ok]),
                    "omega_max": _median([r.get("omega_max") for r in ok]),
                    "step_s": _median([r.get("step_s") for r in ok]),
                    "errors": sorted(
                        {
                            (r.get("error") or "").split("\n")[0][:160]
                            for r in mine
                            if r.get("status") != "ok"
                        }
                    ),
                }
            )
        # a method with failed runs is not on the front: its error is unknown for some cases
        cost = [b["wall_per_sim_s"] if b["runs_failed"] == 0 else math.nan for b in block]
        front: Sequence[bool] | np.ndarray = (
            pareto_front(cost, [b["tip_error_rms"] for b in block]) if block else []
        )
        for b, flag in zip(block, front):
            b["pareto"] = bool(flag)
        out += block
    return out


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        if not math.isfinite(value):
            return "-"
        return f"{value:.3g}"
    return str(value)


def _plot(summary: list[dict[str, Any]], path: Path) -> None:
    from matplotlib.figure import Figure

    from flexctrl.analysis.pareto_compare import error_cost_axes

    scenes = list(dict.fromkeys(s["scene"] for s in summary))
    ncols = min(2, len(scenes))
    nrows = math.ceil(len(scenes) / ncols)
    fig = Figure(figsize=(7.0 * ncols, 5.6 * nrows), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
    colours = {"rigid": "tab:gray", "amm": "tab:blue", "fem": "tab:red"}
    markers = {"rk4": "o", "newmark": "s", "idas": "^", "cvodes": "v", "scipy": "D"}
    for ax, scene in zip(axes, scenes):
        block = [
            s
            for s in summary
            if s["scene"] == scene
            and math.isfinite(s["wall_per_sim_s"])
            and math.isfinite(s["tip_error_rms"])
        ]
        for s in block:
            family = s["model"].split(":")[0].split("+")[0]
            integ = s["integrator"].split("@")[0].split(":")[0]
            ax.scatter(
                s["wall_per_sim_s"],
                1e3 * max(s["tip_error_rms"], 1e-12),
                c=colours.get(family, "k"),
                marker=markers.get(integ, "x"),
                s=70 if s["pareto"] else 28,
                edgecolors="k" if s["pareto"] else "none",
                zorder=3,
                alpha=1.0 if s["runs_failed"] == 0 else 0.4,
            )
            ax.annotate(
                s["method"] + (" (failed runs)" if s["runs_failed"] else ""),
                (s["wall_per_sim_s"], 1e3 * max(s["tip_error_rms"], 1e-12)),
                fontsize=6,
                xytext=(3, 3),
                textcoords="offset points",
            )
        front = sorted((s for s in block if s["pareto"]), key=lambda s: s["wall_per_sim_s"])
        if front:
            xs = [s["wall_per_sim_s"] for s in front]
            ys = [1e3 * max(s["tip_error_rms"], 1e-12) for s in front]
            ax.step(
                xs, ys, where="post", color="k", lw=1.0, ls="--", label="Pareto front", zorder=2
            )
        families = {s["model"].split(":")[0].split("+")[0] for s in block}
        integrators = {s["integrator"].split("@")[0].split(":")[0] for s in block}
        for family in sorted(families):
            ax.scatter([], [], c=colours.get(family, "k"), marker="o", s=28, label=family)
        for integ in sorted(integrators):
            ax.scatter([], [], c="0.5", marker=markers.get(integ, "x"), s=28, label=integ)
        ax.legend(
            fontsize=7, loc="lower left", ncol=2
        )  # the fast-and-accurate corner is empty but for the front
        error_cost_axes(ax, scene)
    for ax in axes[len(scenes) :]:
        ax.set_visible(False)
    fig.suptitle(
        "speed against accuracy (colour: model family; marker: integrator; large = Pareto-optimal)",
        fontsize=9,
    )
    fig.savefig(path, dpi=110)


def report_sections(directory: Path, rows: list[dict], figures: Path) -> list[str]:
    """The Pareto chart, ``pareto.csv`` and the tables, from the result files alone."""
    directory, figures = Path(directory), Path(figures)
    if not any(r.get(METHOD_COLUMN) for r in rows):
        return ["## Speed against accuracy", "", f"No runs with a `{METHOD_COLUMN}` column yet."]
    summary = summarise(rows)
    columns = [
        "scene",
        "method",
        "model",
        "integrator",
        "runs_ok",
        "runs_failed",
        "wall_per_sim_s",
        "tip_error_rms",
        "tip_error_rms_worst",
        "tip_error_max_worst",
        "n_states",
        "omega_max",
        "step_s",
        "pareto",
    ]
    with open(directory / "pareto.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(columns)
        for s in summary:
            writer.writerow([repr(s[c]) if isinstance(s[c], float) else s[c] for c in columns])
    figures.mkdir(parents=True, exist_ok=True)
    chart = figures / "pareto.png"
    _plot(summary, chart)
    lines = [
        "## Speed against accuracy",
        "",
        f"![error against cost]({chart.relative_to(directory).as_posix()})",
        "",
        "Cost: integration wall time per simulated second (median over repeats, then over the "
        "cases); "
        "error: RMS over time of the tip distance from the reference (median over the cases; "
        "worst: the largest "
        "over the cases). Pareto: no other method is both cheaper and more accurate (methods "
        "with failed runs are "
        "not eligible). Numbers also in `pareto.csv`.",
        "",
    ]
    for scene in dict.fromkeys(s["scene"] for s in summary):
        block = sorted(
            (s for s in summary if s["scene"] == scene),
            key=lambda s: (not math.isfinite(s["wall_per_sim_s"]), s["wall_per_sim_s"]),
        )
        lines += [
            f"### {scene}",
            "",
            "| method | states | s per sim. s | tip RMS (m), median | worst RMS (m) | worst max "
            "(m) | runs ok/failed | Pareto |",
            "| --- | --- | --- | --- | --- | --- | --- | --- |",
        ]
        for s in block:
            lines.append(
                f"| `{s['method']}` | {_fmt(s['n_states']).replace('.0', '')} | "
                f"{_fmt(s['wall_per_sim_s'])} | {_fmt(s['tip_error_rms'])} | "
                f"{_fmt(s['tip_error_rms_worst'])} | {_fmt(s['tip_error_max_worst'])} | "
                f"{s['runs_ok']}/{s['runs_failed']} | {'**yes**' if s['pareto'] else ''} |"
            )
        failed = [s for s in block if s["errors"]]
        if failed:
            lines += [""] + [f"- `{s['method']}` failed: {'; '.join(s['errors'])}" for s in failed]
        lines.append("")
    lines += _reference_table(rows)
    return lines


def _reference_table(rows: list[dict]) -> list[str]:
    """One row per (scene, payload, configuration): the reference's convergence evidence."""
    checks = sorted(
        {
            c[len("ref_") : -len("_max")]
            for r in rows
            for c in r
            if c.startswith("ref_") and c.endswith("_max")
        }
    )
    if not checks:
        return []
    coords = [c for c in ("scene", "payload", "q1", "q2", "q3") if any(c in r for r in rows)]
    seen: dict[tuple, dict] = {}
    for r in rows:
        if r.get("status") == "ok":
            seen.setdefault(tuple(r.get(c) for c in coords), r)
    lines = [
        "### The reference and its convergence",
        "",
        "Tip distance (m, RMS / max over time) of each convergence run from the reference: "
        "`step2` is the same model "
        "with half the step; `femN` another mesh with the reference's integrator. `travel` is "
        "the largest distance of "
        "the reference tip from its start.",
        "",
        "| " + " | ".join([*coords, "travel (m)", *checks, "ref. s per sim. s"]) + " |",
        "| " + " | ".join(["---"] * (len(coords) + len(checks) + 2)) + " |",
    ]
    for key, r in seen.items():
        cells = [_fmt(v) for v in key] + [_fmt(r.get("tip_travel"))]
        cells += [f"{_fmt(r.get(f'ref_{c}_rms'))} / {_fmt(r.get(f'ref_{c}_max'))}" for c in checks]
        cells.append(_fmt(r.get("ref_wall_per_sim_s")))
        lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]
