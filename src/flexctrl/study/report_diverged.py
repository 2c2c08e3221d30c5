"""The study report's list of diverged runs: finished runs whose loop diverged, kept apart from
the rankings of the runs that did not."""

from __future__ import annotations

from flexctrl.study.column_units import display
from flexctrl.study.report_context import ReportContext, md_table


def diverged_section(ctx: ReportContext) -> list[str]:
    """``## Diverged runs``: each ok run with a finite ``divergence_time``, when it diverged and
    why its empty cells are empty (the run's ``error`` cell)."""
    lines = ["## Diverged runs"]
    rows = sorted(ctx.diverged_rows(), key=lambda r: r["divergence_time"])
    if not rows:
        return lines + ["", "None."]
    shown = display("divergence_time")
    lines += [
        "",
        f"{len(rows)} run(s) diverged and were stopped: their residual metrics and settling time "
        "are empty, `stable` is 0, and rankings of measured metrics leave them out.",
        "",
    ]
    return lines + md_table(
        ["run_id", *ctx.coords, shown.label, "empty cells and why"],
        [
            (
                r["run_id"],
                *(r.get(c) for c in ctx.coords),
                shown.value(r["divergence_time"]),
                (r.get("error") or "")[:300],
            )
            for r in rows
        ],
    )
