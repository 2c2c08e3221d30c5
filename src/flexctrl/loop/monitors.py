"""Divergence monitors: the bounds beyond which a closed-loop run has left the model's validity."""

from __future__ import annotations

import math

import numpy as np

from flexctrl.sim.bound import BoundFunction

#: Bounds beyond which the plant is declared diverged: |modal coordinate| (m), |rate| (rad/s or
#: m/s).
MODAL_BOUND = 10.0


RATE_BOUND = 1e4


class LoopMonitor:
    """``monitor(t, x) -> str | None`` of :func:`divergence_monitor`, and :meth:`flags`.

    :meth:`flags` judges many states at once.
    """

    def __init__(self, plant, arm, start_q, target_q, fraction: float, margin: float):
        self.n, self.N = plant.n_u, plant.n_q
        self.lengths = np.array([link.length for link in arm.links], dtype=float)
        self.fraction, self.margin = float(fraction), float(margin)
        self.limit = self.fraction * self.lengths
        self.start, self.target = (
            np.asarray(start_q, dtype=float),
            np.asarray(target_q, dtype=float),
        )
        self.low = np.minimum(self.start, self.target) - margin
        self.high = np.maximum(self.start, self.target) + margin
        self.deflection = plant.functions["deflection"]

    def flags(self, X: np.ndarray) -> np.ndarray:
        """For states ``X`` (rows): whether :meth:`__call__` objects to each (one mapped call)."""
        X = np.asarray(X, dtype=float)
        if not X.shape[0]:
            return np.zeros(0, dtype=bool)
        w = np.array(self.deflection.map(X.shape[0])(X[:, : self.N].T)[0], dtype=float).T
        q = X[:, : self.n]
        return np.any(np.abs(w) > self.limit, axis=1) | np.any(
            (q < self.low) | (q > self.high), axis=1
        )

    def __call__(self, t: float, x: np.ndarray) -> str | None:
        return self.verdict(np.array(self.deflection(x[: self.N])[0], dtype=float).ravel(), x)

    def for_run(self):
        """This monitor as ``monitor(t, x)``, its deflections through a buffer bound for one run.

        The Python loop calls the monitor every sample; a bound call skips the DM conversions.
        One per run, so two runs in the threads of one Dask worker share no buffer.
        """
        deflection = BoundFunction(self.deflection)
        return lambda t, x: self.verdict(deflection(x[: self.N])[0].ravel(), x)

    def verdict(self, w: np.ndarray, x: np.ndarray) -> str | None:
        """What :meth:`__call__` says of state ``x`` whose link tip deflections (m) are ``w``."""
        over = np.flatnonzero(np.abs(w) > self.limit)
        if over.size:
            i = int(over[0])
            return (
                f"link {i + 1} tip deflection {w[i]:.3g} m beyond {self.limit[i]:.3g} m "
                f"(divergence_deflection = {self.fraction:g} of its {self.lengths[i]:g} m length)"
            )
        q = x[: self.n]
        out = np.flatnonzero((q < self.low) | (q > self.high))
        if out.size:
            i = int(out[0])
            return (
                f"joint {i + 1} at {math.degrees(q[i]):.4g} deg, more than divergence_angle = "
                f"{math.degrees(self.margin):g} deg outside its move "
                f"[{math.degrees(self.start[i]):.4g}, "
                f"{math.degrees(self.target[i]):.4g}] deg"
            )
        return None


def divergence_monitor(
    plant, arm, start_q, target_q, fraction: float, margin: float
) -> LoopMonitor:
    """``monitor(t, x)`` for the closed loop: link tip deflections and joint excursions.

    A link diverges when its tip deflection exceeds ``fraction`` of its length (m); a
    joint when it leaves the range of its move widened by ``margin`` (rad) on each side.
    """
    return LoopMonitor(plant, arm, start_q, target_q, fraction, margin)
