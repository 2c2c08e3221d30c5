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
    scene's band (default 1 mm) until the end.
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

The verdicts of :func:`run_metrics`:

``settled``
    1 when the tip stays inside ``band`` to the end of a run that did not diverge;
    otherwise 0 and ``settling_time`` is NaN.
``final_tip_error``
    Largest tip error (m) of the last :data:`FINAL_WINDOW` s.
``stable``
    1 when the run did not diverge and, where a linear verdict is given, the linear closed
    loop's spectral radius is below 1.
``settled_within_band``
    1 when the run did not diverge and ``final_tip_error <= stable_band`` (a stable but slow
    loop, or one held in a saturated limit cycle, gets 0 here and 1 in ``stable``).
``divergence_time``
    When the run diverged (s); NaN when it did not.

A metric that does not apply to a run is NaN (an empty cell in a study table), with the
reason in :func:`metric_notes`: the residual metrics and ``settling_time`` of a run that
diverged (the window may never have opened; what it would measure is the divergence), and
``settling_time`` of a run that never settled.
``closed_loop_radius``
    The linear verdict (:func:`flexctrl.loop.verdict.linear_closed_loop_radius`), when given.
``torque_limit_exceeded``
    Whether any applied torque went beyond its joint's limit.

For a payload-aware controller (:mod:`flexctrl.control.payload`), :func:`payload_metrics`:

``payload_estimate_error``
    ``|estimate - truth|`` of the payload at the end of the run (kg).
``payload_estimate_time``
    Time (s) from which the estimate stays within :data:`PAYLOAD_BAND` of the truth to the end;
    NaN (an empty cell) when it never does.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

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
    error = np.linalg.norm(
        np.asarray(tip, dtype=float) - np.asarray(tip_target, dtype=float)[None, :], axis=1
    )
    window = t >= t_arrive + settle_allowance
    if not np.any(window):
        raise ValueError(
            f"the residual-vibration window is empty: the run ends at {t[-1]:g} s but the window "
            f"starts at t_arrive + settle_allowance = {t_arrive + settle_allowance:g} s; lengthen "
            "the scene's duration"
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
        "tracking_error_rms": float(
            np.sqrt(np.mean((np.asarray(joints) - np.asarray(joint_reference)) ** 2))
        ),
        "controller_time_median": float(np.median(times)) if times.size else 0.0,
        "controller_time_p95": float(np.percentile(times, 95)) if times.size else 0.0,
        "controller_time_max": float(np.max(times)) if times.size else 0.0,
        "fallbacks": int(fallbacks),
        "solver_failures": int(solver_failures),
    }


#: Band (kg) the payload estimate must stay within for ``payload_estimate_time``.
PAYLOAD_BAND = 0.2


def payload_metrics(trace: dict, truth, band: float = PAYLOAD_BAND) -> dict:
    """``payload_estimate_error`` (kg) and ``payload_estimate_time`` (s) of an estimate's trace.

    Parameters
    ----------
    trace : dict
        ``time`` (s) and ``mean`` (kg) arrays: the estimate at every controller sample.
    truth : float or callable
        The plant's payload, kg, or ``truth(time) -> kg`` per sample (a payload that changes).
    band : float
        kg.

    Returns
    -------
    dict
        Empty when the trace is.

    Examples
    --------
    >>> import numpy as np
    >>> m = payload_metrics({"time": np.arange(4.0), "mean": np.array([2.0, 1.5, 1.1, 1.05])}, 1.0)
    >>> round(m["payload_estimate_error"], 3), m["payload_estimate_time"]
    (0.05, 2.0)
    """
    t, mean = np.asarray(trace["time"], dtype=float), np.asarray(trace["mean"], dtype=float)
    if t.size == 0:
        return {}
    true = np.broadcast_to(np.asarray(truth(t) if callable(truth) else truth, dtype=float), t.shape)
    error = np.abs(mean - true)
    outside = np.nonzero(error > band)[0]
    if outside.size == 0:
        since = float(t[0])
    else:
        since = float(t[outside[-1] + 1]) if outside[-1] + 1 < t.size else math.nan
    return {"payload_estimate_error": float(error[-1]), "payload_estimate_time": since}


#: Length (s) of the end of a run whose largest tip error decides ``stable`` (with the
#: ``stable_band``).
FINAL_WINDOW = 1.0


def run_metrics(
    trajectory,
    *,
    tip_target,
    reference_joints: np.ndarray,
    t_arrive: float,
    settle_allowance: float,
    band: float,
    stable_band: float,
    torque_limits: Sequence[float],
    controller_stats: dict,
    step_times: Sequence[float] = (),
    radius: float | None = None,
) -> dict:
    """Every metric of one closed-loop run: :func:`closed_loop_metrics` and the verdicts.

    The verdicts (``settled``, ``final_tip_error``, ``stable``, ``divergence_time``,
    ``closed_loop_radius``, ``torque_limit_exceeded``) are defined in the module docstring.
    A diverged run has NaN residual metrics and ``settling_time`` (:func:`metric_notes`
    says why).

    Parameters
    ----------
    trajectory : flexctrl.sim.trajectory.Trajectory
        The plant's run; ``meta["divergence"]`` is None or ``{"time": s, ...}``.
    tip_target : (2,) m
    reference_joints : (T, n) rad, the joint reference on the trajectory's times
    t_arrive, settle_allowance : s
    band, stable_band : m
    torque_limits : (n,) N m
    controller_stats : dict
        ``controller.stats.summary()`` (``fallbacks``, ``status`` counts).
    step_times : s per controller step
    radius : float, optional
        The linear verdict.
    """
    divergence = trajectory.meta.get("divergence")
    tip_target = np.asarray(tip_target, dtype=float)
    n = trajectory.inputs.shape[1]
    if divergence is not None and trajectory.time[-1] < t_arrive + settle_allowance:
        settle_allowance = float(trajectory.time[-1]) - t_arrive - 1e-9
    status = controller_stats.get("status", {})
    metrics = closed_loop_metrics(
        trajectory.time,
        trajectory.tip,
        tip_target,
        trajectory.deflections,
        trajectory.inputs,
        trajectory.states[:, :n],
        reference_joints,
        t_arrive=t_arrive,
        settle_allowance=settle_allowance,
        band=band,
        controller_times=step_times,
        fallbacks=controller_stats.get("fallbacks", 0),
        solver_failures=sum(
            v for k, v in status.items() if not k.startswith(("ok", "solved", "fallback"))
        ),
    )
    if divergence is not None:
        metrics["tip_residual_rms"] = metrics["tip_residual_peak"] = math.nan
    if radius is not None:
        metrics["closed_loop_radius"] = radius
    _add_verdicts(metrics, trajectory, tip_target, stable_band=stable_band, radius=radius)
    limits = np.asarray(torque_limits, dtype=float)
    metrics["torque_limit_exceeded"] = bool(
        np.any(np.max(np.abs(trajectory.inputs), axis=0) > limits * (1 + 1e-9))
    )
    return metrics


def _add_verdicts(
    metrics: dict,
    trajectory,
    tip_target: np.ndarray,
    *,
    stable_band: float,
    radius: float | None,
) -> None:
    """Add ``settled``, ``final_tip_error``, ``settled_within_band``, ``stable`` and
    ``divergence_time`` to ``metrics``."""
    divergence = trajectory.meta.get("divergence")
    metrics["settled"] = int(divergence is None and math.isfinite(metrics["settling_time"]))
    if not metrics["settled"]:
        metrics["settling_time"] = math.nan
    error = np.linalg.norm(trajectory.tip - tip_target[None, :], axis=1)
    final = trajectory.time >= trajectory.time[-1] - FINAL_WINDOW
    metrics["final_tip_error"] = float(np.max(error[final]))
    metrics["settled_within_band"] = int(
        divergence is None and metrics["final_tip_error"] <= stable_band
    )
    metrics["stable"] = int(divergence is None and (radius is None or radius < 1.0))
    metrics["divergence_time"] = math.nan if divergence is None else float(divergence["time"])


def metric_notes(
    metrics: dict, divergence: dict | None, *, window_start: float, band: float
) -> dict[str, str]:
    """Why each NaN metric of :func:`run_metrics` is empty, by name.

    Parameters
    ----------
    metrics : dict
        :func:`run_metrics`'s.
    divergence : dict or None
        The trajectory's ``meta["divergence"]`` (``time`` in s, ``message``).
    window_start : float
        s: when the residual-vibration window opens.
    band : float
        m: the settling band.

    Returns
    -------
    dict
        Metric name -> one line, for every metric that is NaN.
    """
    if divergence is not None:
        t = float(divergence["time"])
        diverged = f"the run diverged at {t:.4g} s" + (
            f", before its residual window opened at {window_start:.4g} s"
            if t < window_start
            else ""
        )
    notes = {}
    for name, value in metrics.items():
        if not (isinstance(value, float) and math.isnan(value)):
            continue
        if name == "divergence_time":
            notes[name] = "the run did not diverge"
        elif divergence is not None:
            notes[name] = diverged
        elif name == "settling_time":
            notes[name] = f"the tip error never stayed inside the {1e3 * band:g} mm band to the end"
        else:
            notes[name] = "not defined for this run"
    return notes


@dataclass(frozen=True)
class MetricInfo:
    """What one metric of a closed-loop run is: its SI unit, which way is better, its meaning.

    Attributes
    ----------
    unit : str
        SI unit ("" for counts and 0/1 verdicts, "-" for a pure number).
    better : {"lower", "higher"}
        Which values are better; reports rank by it.
    meaning : str
        One line.
    verdict : bool
        True for a judgement of the whole run (``stable`` ...), which a diverged run keeps and
        a ranking compares across diverged and finished runs; False for a measurement of a
        finished run, which rankings take from finished runs only.
    """

    unit: str
    better: Literal["lower", "higher"]
    meaning: str
    verdict: bool = False


#: Every metric of a closed-loop run (:func:`run_metrics`), by name, with its unit, better
#: direction and meaning.  The per-joint lists ``peak_torque`` and ``rms_torque`` appear in a
#: study table as ``peak_torque_1``, ``peak_torque_2`` ...  A metric that does not apply to a
#: run (a residual of a run stopped before its window, ``settling_time`` of a run that never
#: settled) is NaN, written as an empty cell, with the reason in :func:`metric_notes`.
METRIC_INFO: dict[str, MetricInfo] = {
    "tip_residual_rms": MetricInfo("m", "lower", "RMS tip error over the residual window"),
    "tip_residual_peak": MetricInfo("m", "lower", "largest tip error in the residual window"),
    "settling_time": MetricInfo(
        "s", "lower", "time after which the tip error stays inside the settling band"
    ),
    "peak_deflection": MetricInfo("m", "lower", "largest link tip deflection of the run"),
    "tracking_error_rms": MetricInfo("rad", "lower", "RMS joint angle minus reference"),
    "controller_time_median": MetricInfo("s", "lower", "median wall time of a controller step"),
    "controller_time_p95": MetricInfo("s", "lower", "95th percentile of the controller step"),
    "controller_time_max": MetricInfo("s", "lower", "longest controller step"),
    "fallbacks": MetricInfo("", "lower", "controller steps that fell back", verdict=True),
    "solver_failures": MetricInfo("", "lower", "controller solver failures", verdict=True),
    "settled": MetricInfo(
        "", "higher", "1: the tip stays inside the settling band to the end", verdict=True
    ),
    "final_tip_error": MetricInfo("m", "lower", "largest tip error of the run's last second"),
    "settled_within_band": MetricInfo(
        "",
        "higher",
        "1: the run did not diverge and final_tip_error <= stable_band",
        verdict=True,
    ),
    "stable": MetricInfo(
        "",
        "higher",
        "1: no divergence and, where there is one, a linear closed-loop radius below 1",
        verdict=True,
    ),
    "divergence_time": MetricInfo("s", "higher", "when the run diverged", verdict=True),
    "closed_loop_radius": MetricInfo(
        "-", "lower", "spectral radius of the linear closed loop (< 1: stable)", verdict=True
    ),
    "torque_limit_exceeded": MetricInfo(
        "", "lower", "1: an applied torque went beyond its joint's limit", verdict=True
    ),
    "payload_estimate_error": MetricInfo(
        "kg", "lower", "|payload estimate - true payload| at the end of the run", verdict=True
    ),
    "payload_estimate_time": MetricInfo(
        "s", "lower", "time from which the payload estimate stays within 0.2 kg", verdict=True
    ),
    "peak_torque": MetricInfo("N m", "lower", "largest applied torque per joint"),
    "rms_torque": MetricInfo("N m", "lower", "RMS applied torque per joint"),
}
#: Per-joint metrics (lists, one value per joint).
JOINT_METRICS = ("peak_torque", "rms_torque")
#: Every scalar metric of a closed-loop run, by name.
METRICS = tuple(name for name in METRIC_INFO if name not in JOINT_METRICS)
#: SI unit of every metric of :data:`METRIC_INFO`; reports convert them for reading (m -> mm,
#: rad -> deg).
UNITS = {name: info.unit for name, info in METRIC_INFO.items()}
