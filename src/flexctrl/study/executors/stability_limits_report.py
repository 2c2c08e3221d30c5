"""The ``stability_limits`` study's report: the largest stable step per integrator and model
beside theory, its CSV and figure.
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.errors import SpecError

#: Outcomes by ``outcome_code``.
OUTCOMES = ("bracketed", "stable_at_cap", "unstable_at_floor")
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


# -- report ---------------------------------------------------------------------------


def _num(value: Any) -> float | None:
    return float(value) if isinstance(value, (int, float)) and math.isfinite(value) else None


def _text(value: float | None, digits: int = 6) -> str:
    return "" if value is None else f"{value:.{digits}g}"


def _run_facts(directory: Path, row: dict) -> tuple[str, str, str, dict]:
    """Integrator, fidelity, scene label and every metric of a row, from its grid columns and its
    record.

    The record (``runs/<id>.json``) holds every metric even when the study's
    ``metrics`` list keeps some out of ``results.csv``.
    """
    from flexctrl.study.store import ResultStore

    integrator = row.get("scene.integrator")
    fidelity = row.get("fidelity")
    scene_label = row.get("scene") or ""
    record = ResultStore(directory).read_record(str(row.get("run_id"))) or {}
    metrics = {k: v for k, v in (record.get("metrics") or {}).items() if v is not None}
    metrics.update({k: v for k, v in row.items() if v is not None})
    if integrator is None or fidelity is None or not scene_label:
        settings = record.get("settings", {})
        scene_path = settings.get("scene")
        scene_label = scene_label or (Path(scene_path).stem if scene_path else "")
        fidelity = fidelity or settings.get("fidelity")
        for item in settings.get("overrides", []):
            if item.startswith("scene.integrator="):
                integrator = integrator or json.loads(item.split("=", 1)[1])
        if (integrator is None or fidelity is None) and scene_path:
            try:
                from flexctrl.spec.reader import read_toml

                doc = read_toml(scene_path)
                integrator = integrator or doc.get("integrator", "rk4")
                fidelity = fidelity or doc.get("fidelity", "amm:2")
            except (SpecError, OSError):
                pass
    return str(integrator or "?"), str(fidelity or "?"), str(scene_label), metrics


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


def stability_rows(directory: Path, rows: list[dict]) -> tuple[list[str], list[dict[str, Any]]]:
    """The ``stability_limits.csv`` table (columns, rows) from the study table's rows."""
    from flexctrl.study.plan import SETTINGS

    skip = (
        set(CSV_COLUMNS)
        | set(EXTRA_COLUMNS)
        | {
            "scene.integrator",
            "seed",
            "error",
            "wall_time_s",
            "peak_memory_mb",
            "bytes_written",
            "worker",
            "run_id",
            "status",
        }
    )
    known_metrics = {
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
    }
    other = [
        c
        for c in (rows[0] if rows else {})
        if c not in skip
        and c not in known_metrics
        and (c in SETTINGS or "." in c or c.startswith("q") or c == "replicate")
    ]
    out = []
    for original in rows:
        integrator, fidelity, scene_label, row = _run_facts(directory, original)
        ok = row.get("status") == "ok"
        h_theory = _num(row.get("h_theory"))
        theory_text = "inf" if ok and row.get("theory_unbounded") == 1 else _text(h_theory)
        code = _num(row.get("outcome_code"))
        entry = {
            "integrator": integrator,
            "fidelity": fidelity,
            "omega_max": _text(_num(row.get("omega_max")), 8) if ok else "",
            "h_measured": _text(_num(row.get("h_measured")), 8) if ok else "",
            "h_theory": theory_text if ok else "",
            "ratio": _text(_num(row.get("ratio"))),
            "omega_h_measured": _text(_num(row.get("omega_h_measured"))) if ok else "",
            "omega_h_theory": "inf"
            if ok and row.get("theory_unbounded") == 1
            else _text(_num(row.get("omega_h_theory"))),
            "h_unstable": _text(_num(row.get("h_unstable")), 8),
            "outcome": OUTCOMES[int(code)]
            if ok and code is not None
            else ("failed" if not ok else ""),
            "note": _note(row),
            "scene": scene_label,
            "run_id": row.get("run_id", ""),
            "status": row.get("status", ""),
        }
        for column in other:
            value = row.get(column)
            entry[column] = "" if value is None else value
        out.append(entry)
    return list(CSV_COLUMNS) + list(EXTRA_COLUMNS) + other, out


def report_sections(directory: Path, rows: list[dict], figures: Path) -> list[str]:
    """Write ``stability_limits.csv`` and ``figures/stability_limits.png``; return the Markdown section."""
    from flexctrl.analysis.stability.theory import RK4_IMAGINARY_AXIS_LIMIT, RK4_REAL_AXIS_LIMIT
    from flexctrl.sim.rk4 import RK4_STABILITY_LIMIT
    from flexctrl.study.store import atomic_write

    directory = Path(directory)
    columns, table = stability_rows(directory, rows)
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(table)
    atomic_write(directory / "stability_limits.csv", text.getvalue().encode())

    lines = [
        "## Largest stable step (stability_limits)",
        "",
        "Each run perturbs the model's static equilibrium (joints held by constant torques) "
        "along every "
        "vibration mode by +-1e-9 m/rad (two runs; half their difference is watched) and bisects "
        "on the step h of the "
        "real integrator; a probe is unstable when a modal amplitude grows by more than its "
        "growth tolerance over its steps, "
        "or a run fails (see flexctrl/analysis/stability/probe.py and "
        "docs/stability.md). `h_theory` is the largest h with |R(lambda h)| <= 1 for every "
        "eigenvalue lambda of "
        "df/dx at that equilibrium; `omega_max` = max |lambda| (rad/s).",
        "",
        "RK4: the exact limit on the imaginary axis (undamped modes) is omega h = 2 sqrt 2 = "
        f"{RK4_IMAGINARY_AXIS_LIMIT:.4f}; "
        f"the issue's {RK4_STABILITY_LIMIT} is the negative-real-axis limit "
        f"({RK4_REAL_AXIS_LIMIT:.4f}), "
        f"{100 * (1 - RK4_REAL_AXIS_LIMIT / RK4_IMAGINARY_AXIS_LIMIT):.2f} % lower; below, "
        "`h/(2.785/omega)` compares "
        "with the issue's number and `ratio` with the exact theory.",
        "",
        "Files: `stability_limits.csv` (columns integrator, fidelity, omega_max [rad/s], "
        "h_measured [s], h_theory [s; "
        "inf = unconditionally stable], ...).",
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
        issue = _text(h * w / RK4_STABILITY_LIMIT, 5) if (w and h) else ""
        cells = [
            entry["integrator"],
            entry["fidelity"],
            _text(w, 5),
            _text(h, 5),
            entry["h_theory"]
            if entry["h_theory"] in ("", "inf")
            else _text(float(entry["h_theory"]), 5),
            entry["ratio"] and _text(float(entry["ratio"]), 6),
            issue,
            entry["omega_h_measured"] and _text(float(entry["omega_h_measured"]), 5),
            entry["note"].replace("|", "\\|"),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    if any(e["omega_max"] for e in table):
        name = "stability_limits.png"
        _draw(figures / name, table)
        lines += ["", f"![largest stable step]({figures.name}/{name})"]
    return lines


#: Marker and colour per integrator.
STYLES = {"rk4": ("o", "C0"), "euler": ("s", "C3"), "newmark": ("^", "C2")}


def _draw(path: Path, table: list[dict]) -> None:
    """The largest stable steps against omega_max beside theory; RK4's omega_max h zoomed."""
    from matplotlib.figure import Figure

    from flexctrl.analysis.stability.theory import RK4_IMAGINARY_AXIS_LIMIT
    from flexctrl.sim.rk4 import RK4_STABILITY_LIMIT

    fig = Figure(figsize=(11.0, 4.8), layout="constrained")
    ax, zoom = fig.subplots(1, 2, width_ratios=(1.4, 1.0))
    omegas = [float(e["omega_max"]) for e in table if e["omega_max"]]
    span = np.geomspace(min(omegas) / 1.5, max(omegas) * 1.5, 50)
    ax.plot(
        span,
        RK4_IMAGINARY_AXIS_LIMIT / span,
        "k-",
        lw=1,
        label="RK4 theory, undamped: 2 sqrt 2 / omega",
    )
    ax.plot(span, RK4_STABILITY_LIMIT / span, "k--", lw=1, label="2.785 / omega (RK4, real axis)")
    _draw_steps(ax, table)
    _draw_rk4_zoom(zoom, table, RK4_IMAGINARY_AXIS_LIMIT, RK4_STABILITY_LIMIT)
    fig.savefig(path, dpi=100)


def _draw_steps(ax, table: list[dict]) -> None:
    """Each run's largest stable step (s) against omega_max (rad/s), with theory's."""
    styles = STYLES
    seen: set[str] = set()
    for e in table:
        if not e["omega_max"] or e["status"] != "ok":
            continue
        w = float(e["omega_max"])
        marker, colour = styles.get(e["integrator"], ("D", "C7"))
        if e["outcome"] == "unstable_at_floor":
            h, marker, what = (
                float(e["h_unstable"]),
                "v",
                " unstable down to (plotted at the floor)",
            )
        elif e["outcome"] == "stable_at_cap":
            h, what = float(e["h_measured"]), " stable up to the cap (lower bound)"
        else:
            h, what = float(e["h_measured"]), " measured"
        label = e["integrator"] + what
        ax.plot(
            [w],
            [h],
            marker,
            color=colour,
            ms=7,
            mfc="none" if e["outcome"] != "bracketed" else colour,
            label=None if label in seen else label,
        )
        seen.add(label)
        if e["h_theory"] not in ("", "inf") and float(e["h_theory"]) > 0:
            label = e["integrator"] + " theory"
            ax.plot(
                [w],
                [float(e["h_theory"])],
                "x",
                color=colour,
                ms=9,
                label=None if label in seen else label,
            )
            seen.add(label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("omega_max of the linearisation (rad/s)")
    ax.set_ylabel("largest stable step h (s)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="best")


def _draw_rk4_zoom(zoom, table: list[dict], imaginary_limit: float, real_limit: float) -> None:
    """RK4's bracketed rows as omega_max h: the 1.5 % between 2 sqrt 2 and 2.785 shows."""
    styles = STYLES
    zoom.axhline(imaginary_limit, color="k", lw=1, label="2 sqrt 2 (RK4, imaginary axis)")
    zoom.axhline(real_limit, color="k", ls="--", lw=1, label="2.785 (RK4, real axis)")
    seen = set()
    for e in table:
        if (
            e["status"] != "ok"
            or e["outcome"] != "bracketed"
            or not e["omega_h_measured"]
            or e["integrator"] != "rk4"
        ):
            continue
        marker, colour = styles.get(e["integrator"], ("D", "C7"))
        label = e["integrator"] + " measured"
        zoom.plot(
            [float(e["omega_max"])],
            [float(e["omega_h_measured"])],
            marker,
            color=colour,
            ms=7,
            label=None if label in seen else label,
        )
        seen.add(label)
        if e["omega_h_theory"] not in ("", "inf"):
            label = e["integrator"] + " theory"
            zoom.plot(
                [float(e["omega_max"])],
                [float(e["omega_h_theory"])],
                "x",
                color=colour,
                ms=9,
                label=None if label in seen else label,
            )
            seen.add(label)
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
