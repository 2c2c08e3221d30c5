"""Closed-loop runs drawn side by side: tip error, link deflections, torques and joint angles."""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

#: Link line styles (the colour is the run's).
_LINK_STYLES = ("-", "--", ":", "-.")


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
    the joint angles (deg) with the reference dotted.  The residual-vibration window of
    the first run is shaded.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if not results:
        raise ValueError("nothing to draw: give at least one result, e.g. {'LQR': result}")
    fig = Figure(figsize=(8.0, 9.0), layout="constrained")
    FigureCanvasAgg(fig)
    ax_tip, ax_w, ax_u, ax_q = fig.subplots(4, 1, sharex=True)
    first = next(iter(results.values()))
    start, end = first.residual_window
    for ax in (ax_tip, ax_w, ax_u, ax_q):
        ax.axvspan(start, end, color="0.92", zorder=0)
        ax.grid(True, alpha=0.3)
    errors = []
    limits_drawn = False
    for index, (label, result) in enumerate(results.items()):
        colour = f"C{index % 10}"
        traj = result.trajectory
        t = traj.time
        error_mm = 1e3 * result.tip_error
        errors.append(error_mm)
        rms = result.metrics.get("tip_residual_rms", math.nan)
        ax_tip.plot(t, error_mm, color=colour, lw=1.0, label=f"{label} (residual RMS {1e3 * rms:.3g} mm)")
        for link in range(traj.deflections.shape[1]):
            ax_w.plot(t, 1e3 * traj.deflections[:, link], color=colour, lw=0.9,
                      ls=_LINK_STYLES[link % len(_LINK_STYLES)], label=f"{label}, link {link + 1}")
        for joint in range(traj.inputs.shape[1]):
            ax_u.plot(t, traj.inputs[:, joint], color=colour, lw=0.9, ls=_LINK_STYLES[joint % len(_LINK_STYLES)],
                      label=f"{label}, joint {joint + 1}")
            ax_q.plot(t, np.degrees(traj.states[:, joint]), color=colour, lw=0.9,
                      ls=_LINK_STYLES[joint % len(_LINK_STYLES)], label=f"{label}, joint {joint + 1}")
        if not limits_drawn and result.model is not None:
            for joint, spec in enumerate(getattr(result.model.spec, "joints", ())):
                limit = getattr(spec, "torque_limit", math.inf)
                if math.isfinite(limit):
                    for sign in (1, -1):
                        ax_u.axhline(sign * limit, color="k", ls="--", lw=0.7,
                                     label=f"limit joint {joint + 1}: {limit:g} N m" if sign > 0 else None)
            limits_drawn = True
    if first.reference is not None:
        t = first.trajectory.time
        ref = np.degrees(first.reference.joints(t))
        for joint in range(ref.shape[1]):
            ax_q.plot(t, ref[:, joint], color="k", ls=":", lw=0.8, label="reference" if joint == 0 else None)
    positive = np.concatenate([e[e > 0] for e in errors]) if errors else np.array([])
    if positive.size and positive.max() / max(np.percentile(positive, 5), 1e-12) > 100:
        ax_tip.set_yscale("log")  # values span decades; the zero crossings' dips say nothing below 1e-5 of the peak
        ax_tip.set_ylim(bottom=max(float(positive.min()), 1e-5 * float(positive.max())))
    ax_tip.set_ylabel("tip error (mm)")
    ax_w.set_ylabel("link tip deflection (mm)")
    ax_u.set_ylabel("torque (N m)")
    ax_q.set_ylabel("joint angle (deg)")
    ax_q.set_xlabel("time (s)")
    ax_tip.legend(fontsize=7, loc="best")
    for ax in (ax_w, ax_u, ax_q):
        ax.legend(fontsize=6, loc="best", ncol=2)
    ax_tip.set_title(title or f"shaded: residual-vibration window {start:.3g}-{end:.3g} s", fontsize=9)
    return fig
