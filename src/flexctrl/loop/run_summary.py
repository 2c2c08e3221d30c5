"""A finished closed-loop run judged and described: its metrics and ``summary.json``'s content.

Shared by the Python entry point (:func:`flexctrl.loop.closed_loop.closed_loop`) and the
scene runner (:func:`flexctrl.scenes.run_closed_loop_scene.run_closed_loop_scene`), so
both judge and describe a run alike.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from flexctrl.loop.metrics import metric_notes, payload_metrics, run_metrics
from flexctrl.sim.trajectory import Trajectory
from flexctrl.spec.closed_loop_scene import MetricSettings
from flexctrl.spec.reference import JointReference, JointSequence


def judge_run(
    trajectory: Trajectory,
    controller,
    path: JointReference | JointSequence,
    judge: MetricSettings,
    *,
    tip_target: np.ndarray,
    torque_limits: Sequence[float],
    radius: float | None,
    true_payload=None,
) -> dict[str, Any]:
    """Every metric of the run (:func:`flexctrl.loop.metrics.run_metrics`).

    With a payload-aware controller (one with ``payload_trace()``) and ``true_payload``, also
    :func:`flexctrl.loop.metrics.payload_metrics`.

    Parameters
    ----------
    trajectory : Trajectory
        The plant's run.
    controller : Controller
        The controller that ran (its statistics and step times).
    path : JointReference
        The joint path it tracked (rad, s).
    judge : MetricSettings
        The residual window, bands and divergence bounds.
    tip_target : numpy.ndarray
        The tip at rest at the target (m).
    torque_limits : sequence of float
        Per joint (N m).
    radius : float or None
        The linear verdict (:func:`flexctrl.loop.verdict.linear_closed_loop_radius`).
    true_payload : float or callable, optional
        The plant's payload (kg), or ``true_payload(time) -> kg``.
    """
    metrics = run_metrics(
        trajectory,
        tip_target=tip_target,
        reference_joints=path.joints(trajectory.time),
        t_arrive=path.t_arrive,
        settle_allowance=judge.settle_allowance,
        band=judge.band,
        stable_band=judge.stable_band,
        torque_limits=torque_limits,
        controller_stats=controller.stats.summary(),
        step_times=controller.stats.step_times,
        radius=radius,
    )
    trace = getattr(controller, "payload_trace", None)
    if trace is not None and true_payload is not None:
        metrics.update(payload_metrics(trace(), true_payload))
    return metrics


def _damping(plant) -> dict[str, Any] | None:
    """The plant's damping as built (:meth:`flexctrl.spec.arm.ArmSpec.damping_summary`)."""
    spec = getattr(plant, "spec", None)
    if spec is None or not hasattr(spec, "damping_summary"):
        return None
    return spec.damping_summary(getattr(plant, "info", {}).get("damping"))


def run_summary(
    trajectory: Trajectory,
    metrics: dict[str, Any],
    controller,
    *,
    plant,
    payload: float,
    design: dict[str, Any],
    path: JointReference | JointSequence,
    deflection: str,
    tip_target: np.ndarray,
    judge: MetricSettings,
    controller_file: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """``summary.json``'s description of a run besides the scene.

    Parameters
    ----------
    trajectory : Trajectory
        The plant's run.
    metrics : dict
        :func:`judge_run`'s.
    controller : Controller
        The controller that ran.
    plant : Model
        The plant.
    payload : float
        The plant's payload (kg).
    design : dict
        The design model: ``fidelity``, ``payload_kg``, ``configuration_deg``.
    path : JointReference
        The joint path tracked (rad, s).
    deflection : str
        The elastic reference (``"quasi_static"`` or ``"static"``).
    tip_target : numpy.ndarray
        The tip at rest at the target (m).
    judge : MetricSettings
        Its ``settle_allowance`` opens the residual window.
    controller_file : dict, optional
        ``{"file": path or None}`` for a controller from a file, listed first.
    """
    return {
        "controller": {
            **(controller_file or {}),
            "kind": controller.settings.kind,
            "sample_time": controller.sample_time,
            **controller.stats.summary(),
        },
        "plant": {
            "fidelity": str(plant.fidelity),
            "n_states": plant.n_x,
            "payload_kg": payload,
            "damping": _damping(plant),
        },
        "design": design,
        "reference": path.settings() | {"deflection": deflection},
        "tip_target": tip_target.tolist(),
        "window_s": [path.t_arrive + judge.settle_allowance, float(trajectory.time[-1])],
        "metrics": metrics,
        "metric_notes": metric_notes(
            metrics,
            trajectory.meta.get("divergence"),
            window_start=path.t_arrive + judge.settle_allowance,
            band=judge.band,
        ),
        "divergence": trajectory.meta.get("divergence"),
        "wall_time_s": trajectory.meta["wall_time_s"],
    }
