"""The result of a closed-loop run: trajectory, metrics, summary, a figure, files and a table."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.linear import equilibrium
from flexctrl.loop.compare_figure import compare
from flexctrl.sim.trajectory import Trajectory


def tip_at_rest(model, q_joints) -> np.ndarray:
    """The tip position (m) of ``model``'s static equilibrium at the joint angles ``q_joints``.

    ``q_joints`` in rad.
    """
    target = equilibrium(model, tuple(float(a) for a in q_joints))
    return np.array(model.functions["tip"](target.q, target.qd)[0], dtype=float).ravel()


@dataclass
class ClosedLoopResult:
    """A closed-loop run: what :func:`flexctrl.closed_loop` and a closed-loop scene return.

    Attributes
    ----------
    trajectory : Trajectory
        The plant at its own step: states, held torques (N m), tip (m), link tip deflections (m).
    metrics : dict
        :func:`flexctrl.loop.metrics.run_metrics` (SI units: m, s, N m; ``stable`` 0/1).
    summary : dict
        Everything ``summary.json`` holds besides the trajectory's own figures (scene,
        controller, plant, design, reference, tip target, metrics, divergence).
    model : Model
        The plant.
    controller : Controller
        The controller that ran (its ``stats`` hold the step times).
    reference : JointReference
        The joint path the controller tracked (rad).
    scene : ClosedLoopScene or None
        The scene, when the run came from one.
    files : list of Path
        Files written by :meth:`save`.
    payload_estimate : dict or None
        A payload-aware controller's estimate at every sample: ``time`` (s), ``mean``, ``std``
        and ``design`` (the payload designed for), kg; None for other controllers.
    """

    trajectory: Trajectory
    metrics: dict[str, Any]
    summary: dict[str, Any]
    model: Any = None
    controller: Any = None
    reference: Any = None
    scene: Any = None
    files: list[Path] = field(default_factory=list)
    payload_estimate: dict[str, np.ndarray] | None = None

    @property
    def tip_error(self) -> np.ndarray:
        """Distance (m) of the tip from its target at every plant sample."""
        target = np.asarray(self.summary["tip_target"], dtype=float)
        return np.linalg.norm(self.trajectory.tip - target[None, :], axis=1)

    @property
    def residual_window(self) -> tuple[float, float]:
        """Start and end (s) of the residual-vibration window the metrics use."""
        window = self.summary.get("window_s")
        if window is None:
            return float(self.trajectory.time[0]), float(self.trajectory.time[-1])
        return float(window[0]), float(window[1])

    def to_pandas(self):
        """The trajectory as a ``pandas.DataFrame``: the CSV's columns, SI, indexed by time (s)."""
        return self.trajectory.to_pandas()

    def plot(self, label: str | None = None):
        """One figure: tip error, the links' tip deflections, torques and limits, joint angles.

        Returns
        -------
        matplotlib.figure.Figure
            Four panels sharing the time axis (s); the residual window is shaded.
        """
        return compare({label or self.summary.get("controller", {}).get("kind", "run"): self})

    def save(self, directory: str | Path, *, plots: bool = True) -> list[Path]:
        """Write ``trajectory.csv``, ``summary.json`` and (with ``plots``) PNGs into ``directory``.

        Returns the paths written (also kept in :attr:`files`).
        """
        paths = self.trajectory.save(directory, self.summary)
        files = list(paths.values())
        if plots:
            files += self.trajectory.plot(directory)
        self.files = files
        return files

    def __repr__(self) -> str:
        m = self.metrics
        rms = m.get("tip_residual_rms", math.nan)
        return (
            f"ClosedLoopResult(controller={self.summary.get('controller', {}).get('kind')!r}, "
            f"tip_residual_rms={1e3 * rms:.4g} mm, stable={m.get('stable')}, "
            f"duration={float(self.trajectory.time[-1]):.4g} s)"
        )
