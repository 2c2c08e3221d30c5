"""Vibration-suppression metrics of a closed-loop run.

Definitions (all SI; the same in the report and ``summary.json``):

``tip_error(t)``
    Euclidean distance (m) between the last link's tip and the tip target (the tip
    position of the static equilibrium at the target configuration).
residual-vibration window
    From ``t_arrive + settle_allowance`` to the end of the run, where ``t_arrive`` is
    the time at which the joint reference reaches its target (the end of the
    reference trajectory) and ``settle_allowance`` a scene setting (s).  It measures
    what the controller leaves behind after the manoeuvre.
``tip_residual_rms``, ``tip_residual_peak``
    RMS and maximum of ``tip_error`` over that window (m).
``settling_time``
    Time (s, from the start of the run) after which ``tip_error`` stays below the
    scene's band (default 1 mm) until the end; ``inf`` if it never settles.
``peak_deflection``
    Largest absolute tip deflection w_ie of any link over the run (m).
``peak_torque``, ``rms_torque``
    Per joint, over the run (N m).
``tracking_error_rms``
    RMS over the run and the joints of joint angle minus reference (rad).
``controller_time_median``, ``controller_time_p95``, ``controller_time_max``
    Wall time of ``controller.step`` (s).
``fallbacks``, ``solver_failures``
    Counts reported by the controller.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np


def settling_time(t: np.ndarray, error: np.ndarray, band: float) -> float:
    """First time after which ``error`` stays below ``band`` to the end (``inf`` if never)."""
    outside = np.nonzero(error >= band)[0]
    if outside.size == 0:
        return float(t[0])
    last = outside[-1]
    return float(t[last + 1]) if last + 1 < t.size else math.inf


def closed_loop_metrics(
    t: np.ndarray,
    tip: np.ndarray,
    tip_target: Sequence[float],
    deflections: np.ndarray,
    torques: np.ndarray,
    joints: np.ndarray,
    joint_reference: np.ndarray,
    *,
    t_arrive: float,
    settle_allowance: float = 0.5,
    band: float = 1e-3,
    controller_times: Sequence[float] = (),
    fallbacks: int = 0,
    solver_failures: int = 0,
) -> dict[str, float | list[float]]:
    """Metrics of one run (see the module docstring for definitions).

    Parameters
    ----------
    t : (T,) s
    tip : (T, 2) m, world frame
    tip_target : (2,) m
    deflections : (T, n) m, tip deflection of each link
    torques : (T, n) N m, applied (after saturation)
    joints, joint_reference : (T, n) rad
    t_arrive : s
    settle_allowance : s
    band : m
    controller_times : s per controller step
    """
    t = np.asarray(t, dtype=float)
    error = np.linalg.norm(np.asarray(tip, dtype=float) - np.asarray(tip_target, dtype=float)[None, :], axis=1)
    window = t >= t_arrive + settle_allowance
    if not np.any(window):
        raise ValueError(
            f"the residual-vibration window is empty: the run ends at {t[-1]:g} s but the window starts at "
            f"t_arrive + settle_allowance = {t_arrive + settle_allowance:g} s; lengthen the scene's duration"
        )
    torques = np.asarray(torques, dtype=float)
    times = np.asarray(controller_times, dtype=float)
    return {
        "tip_residual_rms": float(np.sqrt(np.mean(error[window] ** 2))),
        "tip_residual_peak": float(np.max(error[window])),
        "settling_time": settling_time(t, error, band),
        "peak_deflection": float(np.max(np.abs(deflections))) if np.size(deflections) else 0.0,
        "peak_torque": np.max(np.abs(torques), axis=0).tolist(),
        "rms_torque": np.sqrt(np.mean(torques**2, axis=0)).tolist(),
        "tracking_error_rms": float(np.sqrt(np.mean((np.asarray(joints) - np.asarray(joint_reference)) ** 2))),
        "controller_time_median": float(np.median(times)) if times.size else 0.0,
        "controller_time_p95": float(np.percentile(times, 95)) if times.size else 0.0,
        "controller_time_max": float(np.max(times)) if times.size else 0.0,
        "fallbacks": int(fallbacks),
        "solver_failures": int(solver_failures),
    }
