"""Divergence monitors: the bounds beyond which a closed-loop run has left the model's validity."""

from __future__ import annotations

import math

import numpy as np

#: Bounds beyond which the plant is declared diverged: |modal coordinate| (m), |rate| (rad/s or m/s).
MODAL_BOUND = 10.0


RATE_BOUND = 1e4


def divergence_monitor(plant, arm, start_q, target_q, fraction: float, margin: float):
    """``monitor(t, x)`` for :func:`simulate_closed_loop`: link tip deflections and joint excursions.

    A link diverges when its tip deflection exceeds ``fraction`` of its length (m); a
    joint when it leaves the range of its move widened by ``margin`` (rad) on each side.
    """
    n, N = plant.n_u, plant.n_q
    lengths = np.array([link.length for link in arm.links], dtype=float)
    limit = fraction * lengths
    start, target = np.asarray(start_q, dtype=float), np.asarray(target_q, dtype=float)
    low, high = np.minimum(start, target) - margin, np.maximum(start, target) + margin
    deflection = plant.functions["deflection"]

    def monitor(t: float, x: np.ndarray) -> str | None:
        w = np.array(deflection(x[:N])[0], dtype=float).ravel()
        over = np.flatnonzero(np.abs(w) > limit)
        if over.size:
            i = int(over[0])
            return (f"link {i + 1} tip deflection {w[i]:.3g} m beyond {limit[i]:.3g} m "
                    f"(divergence_deflection = {fraction:g} of its {lengths[i]:g} m length)")
        q = x[:n]
        out = np.flatnonzero((q < low) | (q > high))
        if out.size:
            i = int(out[0])
            return (f"joint {i + 1} at {math.degrees(q[i]):.4g} deg, more than divergence_angle = "
                    f"{math.degrees(margin):g} deg outside its move [{math.degrees(start[i]):.4g}, "
                    f"{math.degrees(target[i]):.4g}] deg")
        return None

    return monitor

