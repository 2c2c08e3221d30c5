"""Closed-loop runs drawn side by side: tip error, link deflections, torques and joint angles.

:func:`compare` draws :class:`~flexctrl.loop.result.ClosedLoopResult` objects; the study
report (``flexctrl report DIR``) draws the stored trajectories of a study's runs with the
same :func:`draw_runs`, so a worst case of a study and ``fc.compare`` of the same runs
look alike.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flexctrl.errors import keyword_checked

#: Link and joint line styles (the colour is the run's).
_LINK_STYLES = ("-", "--", ":", "-.")


@dataclass
class RunCurves:
    """One run's curves in SI units, as :func:`draw_runs` draws them.

    Attributes
    ----------
    label : str
        The legend's name of the run.
    time : (T,) s
    tip_error : (T,) m, or None when not known
    deflections : (T, links) m, link tip deflections
    torques : (T, joints) N m
    joints : (T, joints) rad, or None
    reference : (T, joints) rad, or None
    torque_limits : sequence of N m (inf: unlimited)
    window : (start, end) s of the residual-vibration window, or None
    residual_rms : m, or None
    payload : dict or None
        A payload-aware controller's estimate: ``time`` (s), ``mean``, ``std``, ``design`` (kg).
    payload_truth : float or None
        The plant's payload, kg.
    """

    label: str
    time: np.ndarray
    tip_error: np.ndarray | None
    deflections: np.ndarray
    torques: np.ndarray
    joints: np.ndarray | None = None
    reference: np.ndarray | None = None
    torque_limits: Sequence[float] = field(default_factory=tuple)
    window: tuple[float, float] | None = None
    residual_rms: float | None = None
    payload: dict | None = None
    payload_truth: float | None = None


@keyword_checked
def compare(results: Mapping[str, object], *, title: str | None = None):
    """Runs drawn on the same axes: ``compare({"PD": res_pd, "LQR": res_lqr})``.

    Parameters
    ----------
    results : mapping of str to ClosedLoopResult
        Label -> run (from :func:`flexctrl.closed_loop` or a scene); the legend shows each
        run's tip residual RMS (mm).
    title : str, optional
        The figure's title (default: the residual window).

    Panels, sharing the time axis (s): the tip's distance from its target (mm; log scale
    when the values span more than two decades), every link's tip deflection (mm; one
    line style per link), the applied torques (N m) with the joints' limits dashed, and
    the joint angles (deg) with the reference dotted and, when a run has a payload-aware
    controller, its payload estimate (kg: mean with a +-2 std band, the design payload as
    steps, the plant's payload dashed).  The residual-vibration window of the first run is
    shaded.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if not results:
        raise ValueError("nothing to draw: give at least one result, e.g. {'LQR': result}")
    return draw_runs([_curves(label, result) for label, result in results.items()], title=title)


def _curves(label: str, result) -> RunCurves:
    traj = result.trajectory
    n = traj.inputs.shape[1]
    spec = getattr(result.model, "spec", None)
    limits = tuple(getattr(j, "torque_limit", math.inf) for j in getattr(spec, "joints", ()))
    reference = None if result.reference is None else result.reference.joints(traj.time)
    return RunCurves(
        label,
        traj.time,
        result.tip_error,
        traj.deflections,
        traj.inputs,
        traj.states[:, :n],
        reference,
        limits,
        result.residual_window,
        result.metrics.get("tip_residual_rms"),
        getattr(result, "payload_estimate", None),
        getattr(getattr(spec, "payload", None), "mass", None),
    )


def draw_runs(runs: Sequence[RunCurves], *, title: str | None = None, highlight: str | None = None):
    """The four-panel figure of :func:`compare` from plain curves (see :class:`RunCurves`).

    ``highlight`` names a run drawn thicker (a study's worst case among its neighbours).
    The first run's window is shaded and the first run's torque limits are drawn; a panel
    whose data no run has (tip error, joint angles) is left out.
    """
    if not runs:
        raise ValueError("nothing to draw: give at least one run")
    fig, axes = _panels(runs)
    first = runs[0]
    run_handles = [_draw_run(axes, index, run, highlight) for index, run in enumerate(runs)]
    limit_handles = _draw_limits(axes["u"], first.torque_limits)
    if "q" in axes and first.reference is not None:
        _draw_reference(axes["q"], first)
    if "tip" in axes:
        _tip_scale(axes["tip"], [r.tip_error for r in runs if r.tip_error is not None])
    _legends(axes, runs, run_handles, limit_handles)
    shaded = (
        f"shaded: residual-vibration window {first.window[0]:.3g}-{first.window[1]:.3g} s"
        if first.window and first.window[0] < first.window[1]
        else f"no residual-vibration window: the run ended at {first.time[-1]:.3g} s, before "
        f"it opened at {first.window[0]:.3g} s"
        if first.window
        else ""
    )
    list(axes.values())[0].set_title("\n".join(t for t in (title, shaded) if t), fontsize=9)
    return fig


def _panels(runs: Sequence[RunCurves]):
    """The figure and its panels by name (``tip``, ``w``, ``u``, ``q``), the window shaded."""
    # matplotlib loads when a figure is drawn, not when a result is made
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    panels = (
        ["tip"] * any(r.tip_error is not None for r in runs)
        + ["w", "u"]
        + ["q"] * any(r.joints is not None for r in runs)
        + ["m"] * any(r.payload is not None for r in runs)
    )
    fig = Figure(figsize=(8.0, 2.25 * len(panels) + 0.6), layout="constrained")
    FigureCanvasAgg(fig)
    axes = dict(zip(panels, np.atleast_1d(fig.subplots(len(panels), 1, sharex=True))))
    labels = {
        "tip": "tip error (mm)",
        "w": "link tip deflection (mm)",
        "u": "torque (N m)",
        "q": "joint angle (deg)",
        "m": "payload estimate (kg)",
    }
    window = runs[0].window
    for key, ax in axes.items():
        if window is not None and window[0] < window[1]:
            ax.axvspan(*window, color="0.9", zorder=0)
        ax.grid(True, alpha=0.3)
        ax.set_ylabel(labels[key])
    list(axes.values())[-1].set_xlabel("time (s)")
    return fig, axes


def _draw_run(axes, index: int, run: RunCurves, highlight: str | None):
    """One run's curves in every panel; returns its legend handle."""
    from matplotlib.lines import Line2D  # loaded when a figure is drawn

    style: dict[str, Any] = {
        "color": f"C{index % 10}",
        "lw": 1.8 if run.label == highlight else 0.9,
        "zorder": 1.5 if run.label == highlight else 2.0,  # the others stay visible over it
    }
    rms = (
        ""
        if run.residual_rms is None
        else " (no residual: no window)"
        if math.isnan(run.residual_rms)
        else f" (residual RMS {1e3 * run.residual_rms:.3g} mm)"
    )
    if "tip" in axes and run.tip_error is not None:
        axes["tip"].plot(run.time, 1e3 * run.tip_error, **style)
    for link in range(run.deflections.shape[1]):
        axes["w"].plot(run.time, 1e3 * run.deflections[:, link], ls=_LINK_STYLES[link % 4], **style)
    for joint in range(run.torques.shape[1]):
        axes["u"].plot(run.time, run.torques[:, joint], ls=_LINK_STYLES[joint % 4], **style)
        if "q" in axes and run.joints is not None:
            axes["q"].plot(
                run.time, np.degrees(run.joints[:, joint]), ls=_LINK_STYLES[joint % 4], **style
            )
    if "m" in axes and run.payload is not None:
        _draw_payload(axes["m"], run, style)
    return Line2D([], [], label=f"{run.label}{rms}", **style)


def _draw_payload(ax, run: RunCurves, style: dict) -> None:
    """The estimate's mean with a +-2 std band, the design payload as steps, the truth dashed."""
    p = run.payload
    if p is None:
        return
    ax.plot(p["time"], p["mean"], **style)
    low, high = p["mean"] - 2 * p["std"], p["mean"] + 2 * p["std"]
    ax.fill_between(p["time"], low, high, color=style["color"], alpha=0.15, lw=0)
    ax.step(p["time"], p["design"], where="post", ls="--", **{**style, "lw": 0.7})
    if run.payload_truth is not None:
        ax.axhline(run.payload_truth, color="k", ls=":", lw=0.8)


def _draw_limits(ax, limits: Sequence[float]) -> list:
    """The finite torque limits (N m) as lines at plus and minus; returns their legend handles."""
    from matplotlib.lines import Line2D  # loaded when a figure is drawn

    handles = []
    for joint, limit in enumerate(limits):
        if not math.isfinite(limit):
            continue
        ls = _LINK_STYLES[joint % 4]
        for sign in (1, -1):
            ax.axhline(sign * limit, color="k", ls=ls, lw=0.6, alpha=0.7)
        label = f"limit joint {joint + 1}: ±{limit:g} N m"
        handles.append(Line2D([], [], color="k", ls=ls, lw=0.6, label=label))
    return handles


def _draw_reference(ax, run: RunCurves) -> None:
    """The joint reference (deg) dotted, with its legend."""
    from matplotlib.lines import Line2D  # loaded when a figure is drawn

    assert run.reference is not None
    for joint in range(run.reference.shape[1]):
        ax.plot(run.time, np.degrees(run.reference[:, joint]), color="k", ls=":", lw=0.8)
    ax.legend(
        handles=[Line2D([], [], color="k", ls=":", lw=0.8, label="reference")],
        fontsize=7,
        loc="best",
    )


def _legends(axes, runs: Sequence[RunCurves], run_handles: list, limit_handles: list) -> None:
    """The runs' legend on the top panel, the line styles' and the limits' on theirs."""
    from matplotlib.lines import Line2D  # loaded when a figure is drawn

    n_styles = max(run.deflections.shape[1] for run in runs)
    styles = [
        Line2D([], [], color="0.3", lw=0.9, ls=_LINK_STYLES[k % 4], label=f"link / joint {k + 1}")
        for k in range(n_styles)
    ]
    list(axes.values())[0].legend(handles=run_handles, fontsize=7, loc="best")
    axes["w"].legend(handles=styles, fontsize=6.5, loc="best", ncol=len(styles))
    if limit_handles:
        axes["u"].legend(handles=limit_handles, fontsize=6.5, loc="best", ncol=len(limit_handles))


def _tip_scale(ax, errors: list[np.ndarray]) -> None:
    """A log axis when the tip errors span more than two decades (down to 1e-7 of the peak).

    The move's metre-scale start and the residual window's micrometre ringing both stay
    in view; only the dips of the zero crossings are cut.
    """
    positive = np.concatenate([e[e > 0] for e in errors]) if errors else np.array([])
    if positive.size and positive.max() / max(np.percentile(positive, 5), 1e-12) > 100:
        ax.set_yscale("log")
        ax.set_ylim(
            bottom=1e3 * max(float(np.percentile(positive, 1)), 1e-7 * float(positive.max()))
        )
