"""The largest stable steps of many runs: their metrics, table, figure and text.

:func:`result_metrics` turns one :class:`~flexctrl.analysis.stability.step_search.StabilityResult`
into plain metrics (SI units, codes for the outcome and the failure); the rest works on
rows of such metrics, one per run with its ``integrator``, ``fidelity`` and ``scene``
(:func:`limits_table`), and draws ``h`` against ``omega_max`` on log axes with the RK4
lines ``2 sqrt 2 / omega`` and ``2.785 / omega`` (:func:`draw_limits`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from flexctrl.analysis.stability.step_search import StabilityResult
from flexctrl.analysis.stability.theory import RK4_IMAGINARY_AXIS_LIMIT, RK4_REAL_AXIS_LIMIT
from flexctrl.sim.rk4 import RK4_STABILITY_LIMIT

#: Outcomes by ``outcome_code``.
OUTCOMES = ("bracketed", "stable_at_cap", "unstable_at_floor")
#: Why the smallest unstable step failed, by ``failure_code`` (see
#: :class:`flexctrl.analysis.stability.probe.Probe`).
FAILURES = ("growth", "diverged", "solver")
_FAILURE_TEXT = ("a mode grows", "the run diverges", "the method's solver fails (e.g. Newton)")
#: The leading columns of ``stability_limits.csv`` (an external check relies on them).
CSV_COLUMNS = ("integrator", "fidelity", "omega_max", "h_measured", "h_theory")
EXTRA_COLUMNS = (
    "ratio",
    "omega_h_measured",
    "omega_h_theory",
    "h_unstable",
    "outcome",
    "note",
    "scene",
    "run_id",
    "status",
)
#: Metrics of :func:`result_metrics` that the table shows through other columns.
KNOWN_METRICS = (
    "omega_max_model",
    "theory_unbounded",
    "outcome_code",
    "failure_code",
    "h_cap",
    "h_floor",
    "limiting_omega",
    "limiting_zeta",
    "n_modes",
    "n_probes",
    "probe_steps",
    "growth_tolerance",
    "equilibrium_residual",
)


def result_metrics(result: StabilityResult, omega_max_model: float) -> dict[str, float]:
    """The plain metrics of one search (see the ``stability_limits`` executor's docstring).

    ``omega_max_model`` is the model's own ``omega_max`` (rad/s, at its build configuration).
    """
    w = result.omega_max
    metrics: dict[str, float] = {
        "omega_max": w,
        "omega_max_model": float(omega_max_model),
        "h_measured": result.h_measured,
        "theory_unbounded": 1.0 if math.isinf(result.h_theory) else 0.0,
        "omega_h_measured": w * result.h_measured,
        "outcome_code": float(OUTCOMES.index(result.outcome)),
        "h_cap": result.h_cap,
        "h_floor": result.h_floor,
        "n_modes": float(result.n_modes),
        "n_probes": float(len(result.probes)),
        "probe_steps": float(result.criterion.steps),
        "growth_tolerance": result.criterion.growth,
        "equilibrium_residual": result.equilibrium_residual,
    }
    if math.isfinite(result.h_unstable):
        metrics["h_unstable"] = result.h_unstable
    if math.isfinite(result.h_theory):
        metrics["h_theory"] = result.h_theory
        metrics["omega_h_theory"] = w * result.h_theory
    if math.isfinite(result.ratio):
        metrics["ratio"] = result.ratio
    failure = result.first_failure
    if failure is not None:
        metrics["failure_code"] = float(FAILURES.index(failure.kind))
    limiting = result.theory.limiting_eigenvalue if result.theory is not None else None
    if limiting is not None:
        metrics["limiting_omega"] = abs(limiting)
        metrics["limiting_zeta"] = max(-limiting.real / abs(limiting), 0.0)
    return metrics


def probe_histories(result: StabilityResult) -> dict[str, np.ndarray]:
    """``probe_h`` (s), ``probe_stable`` (1/0) and ``probe_growth`` of every probe, in order."""
    return {
        "probe_h": np.array([p.h for p in result.probes]),
        "probe_stable": np.array([1.0 if p.stable else 0.0 for p in result.probes]),
        "probe_growth": np.array([p.growth for p in result.probes]),
    }


def _num(value: Any) -> float | None:
    return float(value) if isinstance(value, (int, float)) and math.isfinite(value) else None


def _text(value: float | None, digits: int = 6) -> str:
    return "" if value is None else f"{value:.{digits}g}"


def _note(row: dict) -> str:
    if row.get("status") != "ok":
        return f"failed: {row.get('error', '')}"
    code = _num(row.get("outcome_code"))
    w = _num(row.get("omega_max")) or math.nan
    if code == 1:
        cap = _num(row.get("h_cap")) or math.nan
        return (
            f"stable at every tested step up to the cap h = {cap:.4g} s (omega_max h = "
            f"{w * cap:.4g}); h_measured is that cap (a lower bound)"
        )
    if code == 2:
        floor = _num(row.get("h_floor")) or math.nan
        return (
            f"unstable at every tested step down to h = {floor:.4g} s (omega_max h = "
            f"{w * floor:.3g}); h_measured = 0"
        )
    h, hu = _num(row.get("h_measured")), _num(row.get("h_unstable"))
    failure = _num(row.get("failure_code"))
    why = f": {_FAILURE_TEXT[int(failure)]}" if failure is not None else ""
    return (
        f"stable at {h:.6g} s, unstable at {hu:.6g} s{why}"
        if h is not None and hu is not None
        else "bracketed"
    )


def limits_row(integrator: str, fidelity: str, scene: str, row: dict[str, Any]) -> dict[str, Any]:
    """One run's row of ``stability_limits.csv`` (text cells) from its metrics and status."""
    ok = row.get("status") == "ok"
    unbounded = ok and row.get("theory_unbounded") == 1
    code = _num(row.get("outcome_code"))
    outcome = OUTCOMES[int(code)] if ok and code is not None else ("failed" if not ok else "")
    return {
        "integrator": integrator,
        "fidelity": fidelity,
        "omega_max": _text(_num(row.get("omega_max")), 8) if ok else "",
        "h_measured": _text(_num(row.get("h_measured")), 8) if ok else "",
        "h_theory": ("inf" if unbounded else _text(_num(row.get("h_theory")))) if ok else "",
        "ratio": _text(_num(row.get("ratio"))),
        "omega_h_measured": _text(_num(row.get("omega_h_measured"))) if ok else "",
        "omega_h_theory": "inf" if unbounded else _text(_num(row.get("omega_h_theory"))),
        "h_unstable": _text(_num(row.get("h_unstable")), 8),
        "outcome": outcome,
        "note": _note(row),
        "scene": scene,
        "run_id": row.get("run_id", ""),
        "status": row.get("status", ""),
    }


def markdown_lines(table: Sequence[dict[str, Any]]) -> list[str]:
    """The explanation and the Markdown table of :func:`limits_row` rows."""
    lower = 100 * (1 - RK4_REAL_AXIS_LIMIT / RK4_IMAGINARY_AXIS_LIMIT)
    lines = [
        "Each run perturbs the model's static equilibrium (joints held by constant torques) "
        "along every vibration mode by +-1e-9 m/rad (two runs; half their difference is "
        "watched) and bisects on the step h of the real integrator; a probe is unstable when "
        "a modal amplitude grows by more than its growth tolerance over its steps, or a run "
        "fails (see flexctrl/analysis/stability/probe.py and "
        "docs/explanation/numerical-stability.md). `h_theory` "
        "is the largest h with |R(lambda h)| <= 1 for every eigenvalue lambda of df/dx at "
        "that equilibrium; `omega_max` = max |lambda| (rad/s).",
        "",
        "RK4: the exact limit on the imaginary axis (undamped modes) is omega h = 2 sqrt 2 = "
        f"{RK4_IMAGINARY_AXIS_LIMIT:.4f}; the often quoted {RK4_STABILITY_LIMIT} is the "
        f"negative-real-axis limit ({RK4_REAL_AXIS_LIMIT:.4f}), {lower:.2f} % lower; below, "
        "`h/(2.785/omega)` compares with that number and `ratio` with the exact theory.",
        "",
        "Files: `stability_limits.csv` (columns integrator, fidelity, omega_max [rad/s], "
        "h_measured [s], h_theory [s; inf = unconditionally stable], ...).",
        "",
    ]
    header = [
        "integrator",
        "fidelity",
        "omega_max (rad/s)",
        "h_measured (s)",
        "h_theory (s)",
        "ratio",
        "h/(2.785/omega)",
        "omega h",
        "note",
    ]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for entry in table:
        w = float(entry["omega_max"]) if entry["omega_max"] else None
        h = float(entry["h_measured"]) if entry["h_measured"] else None
        theory = entry["h_theory"]
        cells = [
            entry["integrator"],
            entry["fidelity"],
            _text(w, 5),
            _text(h, 5),
            theory if theory in ("", "inf") else _text(float(theory), 5),
            entry["ratio"] and _text(float(entry["ratio"]), 6),
            _text(h * w / RK4_STABILITY_LIMIT, 5) if (w and h) else "",
            entry["omega_h_measured"] and _text(float(entry["omega_h_measured"]), 5),
            entry["note"].replace("|", "\\|"),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


#: Marker and colour of each integrator in the figure.
STYLES = {"rk4": ("o", "C0"), "euler": ("s", "C3"), "newmark": ("^", "C2")}


def draw_limits(path: Path, table: Sequence[dict[str, Any]]) -> None:
    """Draw the largest stable steps against omega_max, and RK4's omega h, into ``path``."""
    fig = Figure(figsize=(11.0, 4.8), layout="constrained")
    ax, zoom = fig.subplots(1, 2, width_ratios=(1.4, 1.0))
    _draw_steps(ax, table)
    # the same, as omega_max h, for the bracketed rows: the 1.5 % between 2 sqrt 2 and 2.785
    # becomes visible
    _draw_rk4_products(zoom, table)
    fig.savefig(path, dpi=100)


def _once(seen: set[str], label: str) -> str | None:
    """``label`` the first time (a legend entry), None after."""
    if label in seen:
        return None
    seen.add(label)
    return label


def _draw_steps(ax: Any, table: Sequence[dict[str, Any]]) -> None:
    omegas = [float(e["omega_max"]) for e in table if e["omega_max"]]
    span = np.geomspace(min(omegas) / 1.5, max(omegas) * 1.5, 50)
    ax.plot(
        span,
        RK4_IMAGINARY_AXIS_LIMIT / span,
        "k-",
        lw=1,
        label="RK4 theory, undamped: 2 sqrt 2 / omega",
    )
    ax.plot(span, RK4_STABILITY_LIMIT / span, "k--", lw=1, label="2.785 / omega (RK4 real axis)")
    seen: set[str] = set()
    for e in table:
        if not e["omega_max"] or e["status"] != "ok":
            continue
        w = float(e["omega_max"])
        marker, colour = STYLES.get(e["integrator"], ("D", "C7"))
        if e["outcome"] == "unstable_at_floor":
            h, marker = float(e["h_unstable"]), "v"
            what = " unstable down to (plotted at the floor)"
        elif e["outcome"] == "stable_at_cap":
            h, what = float(e["h_measured"]), " stable up to the cap (lower bound)"
        else:
            h, what = float(e["h_measured"]), " measured"
        fill = "none" if e["outcome"] != "bracketed" else colour
        label = _once(seen, e["integrator"] + what)
        ax.plot([w], [h], marker, color=colour, ms=7, mfc=fill, label=label)
        if e["h_theory"] not in ("", "inf") and float(e["h_theory"]) > 0:
            label = _once(seen, e["integrator"] + " theory")
            ax.plot([w], [float(e["h_theory"])], "x", color=colour, ms=9, label=label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("omega_max of the linearisation (rad/s)")
    ax.set_ylabel("largest stable step h (s)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="best")


def _draw_rk4_products(zoom: Any, table: Sequence[dict[str, Any]]) -> None:
    zoom.axhline(RK4_IMAGINARY_AXIS_LIMIT, color="k", lw=1, label="2 sqrt 2 (RK4, imaginary axis)")
    zoom.axhline(RK4_STABILITY_LIMIT, color="k", ls="--", lw=1, label="2.785 (RK4 real axis)")
    seen: set[str] = set()
    for e in table:
        if (
            e["status"] != "ok"
            or e["outcome"] != "bracketed"
            or not e["omega_h_measured"]
            or e["integrator"] != "rk4"
        ):
            continue
        marker, colour = STYLES.get(e["integrator"], ("D", "C7"))
        w = float(e["omega_max"])
        label = _once(seen, e["integrator"] + " measured")
        zoom.plot([w], [float(e["omega_h_measured"])], marker, color=colour, ms=7, label=label)
        if e["omega_h_theory"] not in ("", "inf"):
            label = _once(seen, e["integrator"] + " theory")
            zoom.plot([w], [float(e["omega_h_theory"])], "x", color=colour, ms=9, label=label)
    zoom.set_xscale("log")
    values = [
        float(e["omega_h_measured"])
        for e in table
        if e["integrator"] == "rk4" and e["omega_h_measured"]
    ]
    zoom.set_ylim(min([2.75, *values]) - 0.02, max([2.86, *values]) + 0.02)
    zoom.set_xlabel("omega_max (rad/s)")
    zoom.set_ylabel("omega_max h of RK4")
    zoom.grid(True, which="both", alpha=0.3)
    zoom.legend(fontsize=7, loc="best")
