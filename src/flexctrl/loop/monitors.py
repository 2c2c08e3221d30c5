"""Divergence monitors: the bounds beyond which a closed-loop run has left the model's validity."""

from __future__ import annotations

import math

import numpy as np

from flexctrl.sim.bound import BoundFunction

#: Bounds beyond which the plant is declared diverged: |modal coordinate| (m), |rate| (rad/s or
#: m/s).
MODAL_BOUND = 10.0


RATE_BOUND = 1e4
#: The default deflection bound's fraction of a link's length.
LENGTH_FRACTION = 0.1
#: The default deflection bound's multiple of the static deflection of a joint's torque limit:
#: a step of the full torque overshoots to twice its static deflection (undamped), and the
#: bending moment at a link's root can exceed its own joint's torque by the reaction of the
#: joints beyond it, another factor of up to two.
TORQUE_MULTIPLE = 4.0
#: The default deflection bound's largest fraction of a link's length: beyond half its length
#: the small-deflection beam model behind every fidelity no longer describes the link.
MAX_FRACTION = 0.5


def deflection_bounds(arm, fraction: float | None = None) -> np.ndarray:
    """Per link, the tip deflection (m) beyond which a closed-loop run counts as diverged.

    Parameters
    ----------
    arm : ArmSpec
        Its links' lengths ``L`` (m) and bending stiffnesses ``EI`` (N m^2), its joints'
        torque limits ``tau`` (N m).
    fraction : float, optional
        The bound as this fraction of each link's length.  None (the default): the larger of
        :data:`LENGTH_FRACTION` ``* L`` and :data:`TORQUE_MULTIPLE` ``* tau L^2 / (2 EI)``,
        the tip deflection a constant bending moment equal to the torque limit holds on the
        clamped link, at most :data:`MAX_FRACTION` ``* L``.  A stiff arm keeps 0.1 of its
        length (the shipped arm's torque term is 0.05-0.09 m against 0.15 m); a light one,
        which its torques can bend further than that in an ordinary move, gets the room its
        torques give it.

    Returns
    -------
    numpy.ndarray
        (n_links,) m.
    """
    lengths = np.array([link.length for link in arm.links], dtype=float)
    if fraction is not None:
        return float(fraction) * lengths
    stiffness = np.array([link.EI for link in arm.links], dtype=float)
    torques = np.array([joint.torque_limit for joint in arm.joints], dtype=float)
    static = np.where(np.isfinite(torques), torques * lengths**2 / (2.0 * stiffness), 0.0)
    bound = np.maximum(LENGTH_FRACTION * lengths, TORQUE_MULTIPLE * static)
    return np.minimum(bound, MAX_FRACTION * lengths)


class LoopMonitor:
    """``monitor(t, x) -> str | None`` of :func:`divergence_monitor`, and :meth:`flags`.

    :meth:`flags` judges many states at once.
    """

    def __init__(self, plant, arm, start_q, target_q, fraction: float | None, margin: float):
        self.n, self.N = plant.n_u, plant.n_q
        self.lengths = np.array([link.length for link in arm.links], dtype=float)
        self.fraction, self.margin = fraction, float(margin)
        self.limit = deflection_bounds(arm, fraction)
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
            rule = (
                f"divergence_deflection = {self.fraction:g} of its {self.lengths[i]:g} m length"
                if self.fraction is not None
                else f"the default bound: the larger of {LENGTH_FRACTION:g} of its "
                f"{self.lengths[i]:g} m length and {TORQUE_MULTIPLE:g} times the static "
                "deflection of its joint's torque limit; [metrics] divergence_deflection sets "
                "a fraction of the length instead"
            )
            return f"link {i + 1} tip deflection {w[i]:.3g} m beyond {self.limit[i]:.3g} m ({rule})"
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
    plant, arm, start_q, target_q, fraction: float | None, margin: float
) -> LoopMonitor:
    """``monitor(t, x)`` for the closed loop: link tip deflections and joint excursions.

    A link diverges when its tip deflection exceeds :func:`deflection_bounds` (``fraction``
    of its length, or by default the larger of 0.1 of it and four times what its joint's
    torque limit bends it statically); a joint when it leaves the range of its move widened
    by ``margin`` (rad) on each side.
    """
    return LoopMonitor(plant, arm, start_q, target_q, fraction, margin)
