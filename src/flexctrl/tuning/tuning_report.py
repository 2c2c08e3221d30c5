"""``report.md`` of a tuning: what was tuned, the convergence plot and the before/after table."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

#: Metrics that are lengths in m, shown in mm.
_LENGTHS = ("tip_residual_rms", "tip_residual_peak", "peak_deflection", "final_tip_error")


def metric_unit(metric: str) -> tuple[str, float]:
    """The unit a person reads ``metric`` in, and the factor from SI (m -> mm, s -> ms for solver
    times)."""
    if metric in _LENGTHS:
        return "mm", 1e3
    if metric.startswith(("settling_time", "divergence_time")):
        return "s", 1.0
    if metric.startswith("controller_time"):
        return "ms", 1e3
    if metric.startswith(("peak_torque", "rms_torque")):
        return "N m", 1.0
    return "", 1.0


def _flag(value) -> str:
    return "failed" if value is None else ("yes" if value == 1 else "no")


def _coordinate_header(name: str) -> str:
    if name == "payload":
        return "payload (kg)"
    if name.startswith("q") and name[1:].isdigit():
        return f"{name} (deg)"
    return name


def convergence_figure(result, path: Path) -> Path:
    """Every candidate's objective (feasible: dots; infeasible: crosses at the top), the best so
    far, the start."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    spec = result.spec
    unit, factor = metric_unit(spec.objective.metric)
    fig = Figure(figsize=(7.0, 4.0), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    numbers = np.array([e.number for e in result.evaluations[1:]])
    values = np.array(
        [factor * e.objective if e.feasible else np.nan for e in result.evaluations[1:]]
    )
    feasible = np.isfinite(values)
    if np.any(feasible):
        ax.plot(
            numbers[feasible], values[feasible], "o", ms=3.5, color="C0", label="feasible candidate"
        )
        best = np.fmin.accumulate(np.where(feasible, values, np.inf))
        shown = np.isfinite(best)
        ax.step(numbers[shown], best[shown], where="post", color="C1", lw=1.5, label="best so far")
        top = float(np.nanmax(values))
    else:
        top = 1.0
    if math.isfinite(result.initial.objective):
        start = factor * result.initial.objective
        ax.axhline(
            start,
            color="k",
            ls="--",
            lw=1,
            label=f"as shipped: {start:.3g} {unit}"
            + ("" if result.initial.feasible else " (infeasible)"),
        )
        top = max(top, start)
    if np.any(~feasible):
        ax.plot(
            numbers[~feasible],
            np.full(int(np.sum(~feasible)), top * 1.3),
            "x",
            color="C3",
            ms=4,
            label=f"infeasible ({int(np.sum(~feasible))})",
        )
    finite = [v for v in list(values[feasible]) + [top] if v > 0]
    if finite and max(finite) / min(finite) > 20:
        ax.set_yscale("log")
    ax.set_xlabel("candidate")
    ax.set_ylabel(
        f"{spec.objective.statistic} {spec.objective.metric}" + (f" ({unit})" if unit else "")
    )
    ax.set_title(
        f"{spec.name}: {spec.optimizer.method}, {len(result.evaluations) - 1} candidates",
        fontsize=9,
    )
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def write_report(result) -> list[Path]:
    """Write ``report.md`` and ``figures/convergence.png`` into the tuning's folder; returns the
    paths."""
    spec = result.spec
    out = result.directory
    figure = convergence_figure(result, out / "figures" / "convergence.png")
    unit, factor = metric_unit(spec.objective.metric)

    def fmt(value) -> str:
        return "n/a" if value is None or not math.isfinite(value) else f"{factor * value:.4g}"

    lines = [
        f"# Tuning `{spec.name}`",
        "",
        f"`flexctrl tune {spec.source} --out {out}`: {spec.objective.statistic} of "
        f"`{spec.objective.metric}`"
        f"{f' ({unit})' if unit else ''} over {len(result.initial.scenarios)} scenarios, "
        "starting from "
        f"`{spec.controller}`, {spec.optimizer.method} with {spec.optimizer.evaluations} "
        "candidates "
        f"(population {spec.optimizer.population}, seed {spec.optimizer.seed}).",
        "",
    ]
    lines += _constraint_lines(spec) + _parameter_lines(spec, result.best)
    lines += _result_lines(result, fmt, unit)
    lines += [
        "",
        f"![convergence]({figure.relative_to(out)})",
        "",
        "## Before and after, per scenario",
        "",
    ]
    lines += _scenario_lines(result, fmt, unit)
    infeasible = [e for e in result.evaluations[1:] if not e.feasible]
    if infeasible:
        lines += ["", "## Infeasible candidates (first reasons)", ""]
        for e in infeasible[:10]:
            values = ", ".join(f"{k} = {v:.4g}" for k, v in e.values.items())
            lines.append(f"- {e.number} ({values}): {'; '.join(e.violations[:2])}")
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return [path, figure]


def _constraint_lines(spec) -> list[str]:
    """The constraints every candidate met."""
    c = spec.constraints
    rules = [
        name
        for name, on in (
            ("stable in every scenario", c.stable),
            ("torques within the limits", c.torque_limits),
            ("real-time controller (p95 below the sample time)", c.real_time),
        )
        if on
    ]
    if c.closed_loop_radius is not None:
        rules.append(
            f"linear closed-loop radius below {c.closed_loop_radius:g} where the controller has "
            "a gain"
        )
    return ["Constraints: " + ("; ".join(rules) if rules else "none") + ".", ""]


def _parameter_lines(spec, best) -> list[str]:
    """The table of the tuned keys: bounds, scale, value as shipped and tuned."""
    lines: list[str] = []
    lines += [
        "| key | low | high | scale | as shipped | tuned |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for p in spec.parameters:
        value = None if best is None else best.values.get(p.key, p.initial)
        tuned = "n/a" if best is None else ("default" if value is None else f"{value:.6g}")
        shipped = "default" if p.initial is None else f"{p.initial:.6g}"
        lines.append(f"| `{p.key}` | {p.low:g} | {p.high:g} | {p.scale} | {shipped} | {tuned} |")
    return lines


def _result_lines(result, fmt, unit: str) -> list[str]:
    """The objective as shipped and tuned, and what the tuning ran."""
    best = result.best
    lines: list[str] = []
    lines += ["", "## Result", ""]
    n = len(result.evaluations) - 1
    feasible = sum(e.feasible for e in result.evaluations[1:])
    lines.append(
        f"- as shipped: {fmt(result.initial.objective)} {unit}"
        + (
            ""
            if result.initial.feasible
            else f" (infeasible: {'; '.join(result.initial.violations[:3])})"
        )
    )
    if best is None:
        lines.append(f"- **no feasible candidate** in {n} ({feasible} feasible)")
    else:
        ratio = best.objective / result.initial.objective if result.initial.objective else math.nan
        lines.append(
            f"- tuned: **{fmt(best.objective)} {unit}** (candidate {best.number}; {ratio:.3g} x "
            "as shipped)"
        )
        lines.append(f"- written to `{result.directory / 'controller.toml'}`")
    lines.append(
        f"- {n} candidates, {feasible} feasible; {result.runs_made} closed-loop runs made and "
        f"{result.runs_reused} reused from the store in {result.wall_time_s:.0f} s"
    )
    return lines


def _scenario_lines(result, fmt, unit: str) -> list[str]:
    """Per scenario, the objective and stability before and after."""
    spec = result.spec
    best = result.best
    lines: list[str] = []
    coords = list(result.initial.scenarios[0]["coords"]) if result.initial.scenarios else []
    lines.append(
        "| "
        + " | ".join(
            [_coordinate_header(k) for k in coords]
            + [
                f"{spec.objective.metric} before ({unit})",
                f"after ({unit})",
                "stable before",
                "stable after",
            ]
        )
        + " |"
    )
    lines.append("|" + " --- |" * (len(coords) + 4))
    after_rows = (best or result.initial).scenarios
    for before, after in zip(result.initial.scenarios, after_rows):
        cells = [str(before["coords"].get(k, "")) for k in coords]
        cells += [
            fmt(before.get(spec.objective.metric)),
            fmt(after.get(spec.objective.metric)),
            _flag(before.get("stable")),
            _flag(after.get("stable")),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return lines
