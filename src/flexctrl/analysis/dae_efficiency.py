"""Newmark + Baumgarte against IDAS at equal accuracy: Pan, Scott & Ulsoy's (1990) efficiency claim.

Pan et al. (Sec. 4): "Computer runs showed the current method to be more efficient than existing
codes based on Gear's algorithm."  Two of their constrained problems, the same equations handed to
both integrators (:mod:`flexctrl.dynamics.fem.idas_dae` builds the IDAS side from the same
:class:`~flexctrl.dynamics.fem.rp_arm.RPArmModel`):

* the beam over two bilateral supports, fast push (Buffinton & Kane; 4 elements, 1 s);
* the R-P arm of ``models/rp_arm.toml`` extending 0.4 m while turning 60 deg in 1 s (8 elements,
  1.5 s; the motion of ``studies/scenes/rp_extend_rotate.toml``).

Each method is swept over its accuracy knob (Newmark: the step; IDAS: ``rtol``, ``atol = 1e-3
rtol``, plain index-1 DAE as a Gear-type code integrates it); the error is the largest distance of
the tracked tip from a reference on a 1 ms grid.  The reference is IDAS at ``rtol = 1e-10`` (reduced
runs: 1e-8); a fine Newmark run (full form only) checks it independently.  Wall time is the best of
``repeats`` runs in this process, side by side; the work is also counted in linear solves (Newmark:
one per step, the problems are linear; IDAS: its Newton iterations), which does not depend on the
language each integrator's loop is written in (Newmark: Python + numpy; IDAS: C, residuals in
CasADi's VM). At each target error the wall time of either method is interpolated (log-log) along
its sweep.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from flexctrl.dynamics.fem.idas_dae import simulate_idas
from flexctrl.dynamics.fem.moving_frame import RPMotion
from flexctrl.dynamics.fem.newmark_dae import simulate
from flexctrl.dynamics.fem.rp_arm import RPArmModel
from flexctrl.spec.fem_models import RPArmSpec, load_rp_arm
from flexctrl.spec.shipped import data_root

Array = NDArray[np.float64]
ROOT = data_root()
GRID = 1e-3  # s, the comparison grid
#: Sweep names by IDAS's highest BDF order.
METHODS = {5: "idas", 2: "idas_order2"}
LABELS = {
    "newmark": "Newmark + Baumgarte (step, s)",
    "idas": "IDAS, BDF order <= 5 (rtol)",
    "idas_order2": "IDAS, BDF order <= 2 (rtol)",
}


@dataclass(frozen=True)
class Case:
    """One constrained problem: the model, its initial nodal values (at rest) and the simulated time
    (s)."""

    name: str
    model: RPArmModel
    q0: Array
    duration: float


def beam_case() -> Case:
    """Buffinton & Kane's fast push (Pan Fig 8) as an R-P arm with the housing fixed, driven at
    H."""
    spec = RPArmSpec(
        "beam over supports",
        length=1.0,
        mass_per_length=1.0,
        EI=1.0,
        support_inner=0.75,
        support_outer=1.0,
    )
    model = RPArmModel(spec, RPMotion(C1=0.725, C2=0.7, T=0.7), 4, driven_end="H")
    return Case(
        "beam over supports, fast push (4 elements)",
        model,
        model.initial_shape("static_load", 0.01, "H"),
        1.0,
    )


def arm_case() -> Case:
    """``models/rp_arm.toml``: W 0.3 -> 0.7 m while theta 0 -> 60 deg in 1 s, from rest, 8
    elements."""
    spec = load_rp_arm(ROOT / "models" / "rp_arm.toml")
    model = RPArmModel(spec, RPMotion(C1=0.3, C2=-0.4, T=1.0, dtheta=math.radians(60.0)), 8)
    return Case("R-P arm, extend and rotate (8 elements)", model, np.zeros(model.ndof), 1.5)


def _on_grid(t: Array, y: Array, duration: float) -> tuple[Array, Array]:
    """The samples of ``y(t)`` at the multiples of :data:`GRID` ms (indices into the reference
    grid)."""
    k = np.round(t / GRID)
    keep = np.abs(t - k * GRID) < 1e-9
    return k[keep].astype(int), y[keep]


def newmark_point(case: Case, dt: float, repeats: int = 1, gamma: float = 5.0) -> dict:
    """One Newmark + Baumgarte run (gamma = beta, Eq 49): tip on the grid, violations, wall time
    (best of)."""
    prob = case.model.problem()
    walls = []
    for _ in range(repeats):
        res = simulate(
            prob, case.q0, np.zeros_like(case.q0), case.duration, dt, gamma=gamma, beta=gamma
        )
        walls.append(res.wall_time)
    idx, tip = _on_grid(res.t, res.q[:, case.model.tip], case.duration)
    return {
        "method": "newmark",
        "knob": dt,
        "wall_s": min(walls),
        "idx": idx,
        "tip": tip,
        "max_phi_m": float(res.phi_violation.max()),
        "max_phidot_m_s": float(res.phidot_violation.max()),
        "steps": int(res.t.size - 1),
        "linear_solves": int(res.t.size),
        "factorizations": int(res.t.size),
    }


def idas_point(case: Case, rtol: float, repeats: int = 1, max_order: int = 5) -> dict:
    """One IDAS run (plain index-1 DAE) at ``rtol``: tip on the grid, violations, wall time (best
    of);
    ``linear_solves`` counts its Newton iterations, ``factorizations`` its Jacobian set-ups."""
    walls = []
    for _ in range(repeats):
        res = simulate_idas(
            case.model, case.q0, case.duration, GRID, rtol=rtol, max_order=max_order
        )
        walls.append(res.wall_time)
    return {
        "method": METHODS[max_order],
        "knob": rtol,
        "factorizations": int(res.stats.get("nlinsetups", -1)),
        "wall_s": min(walls),
        "idx": np.arange(res.t.size),
        "tip": res.tip_y,
        "max_phi_m": float(res.phi_violation.max()),
        "max_phidot_m_s": float(res.phidot_violation.max()),
        "steps": int(res.stats.get("nsteps", -1)),
        "linear_solves": int(res.stats.get("nniters", -1)),
    }


def interpolate_wall(points: list[dict], target: float) -> float:
    """Wall time (s) at which a sweep reaches ``target`` error (m), log-log between neighbours; NaN
    if
    the sweep does not bracket it."""
    pts = sorted((p["error_m"], p["wall_s"]) for p in points if p["error_m"] > 0)
    for (e1, w1), (e2, w2) in zip(pts, pts[1:]):
        if e1 <= target <= e2:
            s = (
                (math.log(target) - math.log(e1)) / (math.log(e2) - math.log(e1))
                if e2 > e1
                else 0.0
            )
            return math.exp(math.log(w1) + s * (math.log(w2) - math.log(w1)))
    return math.nan


def targets_in_overlap(errors_a: list[float], errors_b: list[float], count: int = 3) -> list[float]:
    """``count`` log-spaced errors (m) inside the range both sweeps cover (empty if they do not
    overlap)."""
    lo, hi = max(min(errors_a), min(errors_b)), min(max(errors_a), max(errors_b))
    if not lo < hi:
        return []
    return list(np.geomspace(lo, hi, count + 2)[1:-1])


def compare(
    case: Case,
    dts: list[float],
    rtols: list[float],
    rtols_order2: list[float],
    repeats: int = 2,
    newmark_check_dt: float | None = None,
    reference_rtol: float = 1e-10,
) -> dict:
    """The three sweeps against the IDAS reference (``reference_rtol``, BDF order <= 2), and wall
    times at
    equal accuracy: for each IDAS variant, at three errors inside the range it shares with the
    Newmark sweep."""
    ref = idas_point(case, reference_rtol, max_order=2)
    points = (
        [newmark_point(case, dt, repeats) for dt in dts]
        + [idas_point(case, r, repeats) for r in rtols]
        + [idas_point(case, r, repeats, max_order=2) for r in rtols_order2]
    )
    for p in points:
        p["error_m"] = float(np.abs(p["tip"] - ref["tip"][p["idx"]]).max())
    out = {
        "case": case.name,
        "duration_s": case.duration,
        "points": points,
        "peak_tip_m": float(np.abs(ref["tip"]).max()),
        "reference": f"IDAS rtol {reference_rtol:g}, BDF order <= 2",
        "reference_rtol": reference_rtol,
    }
    if newmark_check_dt is not None:
        check = newmark_point(case, newmark_check_dt)
        out["reference_check"] = {
            "newmark_dt_s": newmark_check_dt,
            "max_difference_m": float(np.abs(check["tip"] - ref["tip"][check["idx"]]).max()),
        }
    newmark = [p for p in points if p["method"] == "newmark"]
    rows = []
    for method in ("idas", "idas_order2"):
        other = [p for p in points if p["method"] == method]
        if not other:
            continue
        for target in targets_in_overlap(
            [p["error_m"] for p in newmark], [p["error_m"] for p in other]
        ):
            wn, wi = interpolate_wall(newmark, target), interpolate_wall(other, target)
            rows.append(
                {
                    "idas": method,
                    "target_m": target,
                    "newmark_wall_s": wn,
                    "idas_wall_s": wi,
                    "newmark_over_idas": wn / wi,
                }
            )
    out["equal_accuracy"] = rows
    return out


def plot(results: list[dict], path: Path) -> None:
    """Work-precision (wall time against tip error) and constraint drift against tip error, per
    case."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.0, 7.5), layout="constrained")
    axes = fig.subplots(2, len(results), squeeze=False)
    for c, res in enumerate(results):
        for method, style in (("newmark", "o-"), ("idas", "s--"), ("idas_order2", "^:")):
            label = LABELS[method]
            pts = sorted(
                (p for p in res["points"] if p["method"] == method), key=lambda p: p["error_m"]
            )
            if not pts:
                continue
            err = [p["error_m"] for p in pts]
            axes[0, c].loglog(err, [p["wall_s"] for p in pts], style, label=label)
            axes[1, c].loglog(err, [p["max_phi_m"] for p in pts], style, label=label)
            for p in pts:
                axes[0, c].annotate(
                    f"{p['knob']:g}",
                    (p["error_m"], p["wall_s"]),
                    fontsize=7,
                    textcoords="offset points",
                    xytext=(3, 3),
                )
        axes[0, c].set_title(
            f"{res['case']}\n(peak tip {1e3 * res['peak_tip_m']:.2f} mm)", fontsize=9
        )
        axes[0, c].set_ylabel("wall time (s)")
        axes[1, c].set_ylabel("max |Phi| (m)")
        axes[1, c].set_xlabel(
            "max tip error against the reference, IDAS rtol "
            f"{res.get('reference_rtol', 1e-10):g} (m)"
        )
        for ax in axes[:, c]:
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=8)
    fig.savefig(path, dpi=110)
