"""LQR gains on a grid of scheduling joint angles, interpolated between the grid's nodes.

Each node's gain is a direct LQR design at the equilibrium of that configuration (the joints
not scheduled stay at the operating point); between nodes the gains are interpolated
multilinearly, and outside the grid the nearest edge's gains are used.
"""

from __future__ import annotations

import itertools

import control
import numpy as np
from scipy.interpolate import RegularGridInterpolator

from flexctrl.control.riccati import lqr_gain
from flexctrl.errors import SpecError
from flexctrl.linear import Linearizer, OperatingPoint, discretize, equilibrium
from flexctrl.spec.controller_settings import ScheduleSettings


class GainSchedule:
    """Gains on a grid of scheduling joint angles, interpolated multilinearly.

    Outside the grid the gains of the nearest edge are used.

    Parameters
    ----------
    joints : tuple of int
        The scheduling joints, 1-based.
    grid : tuple of tuple of float
        The grid's joint angles per scheduling joint, rad, increasing.
    gains : ndarray
        The gains at the grid's nodes, shape ``grid shape + (n_u, n_x)``.
    """

    def __init__(
        self, joints: tuple[int, ...], grid: tuple[tuple[float, ...], ...], gains: np.ndarray
    ):
        self.joints = np.asarray(joints, dtype=int) - 1  # 0-based indices into the state
        self.grid = tuple(np.asarray(g, dtype=float) for g in grid)
        self.gains = gains  # grid shape + (n_u, n_x)
        self._shape = gains.shape[-2:]
        self._interp = RegularGridInterpolator(
            self.grid, gains.reshape(gains.shape[:-2] + (-1,)), method="linear"
        )
        self._low = np.array([g[0] for g in self.grid])
        self._high = np.array([g[-1] for g in self.grid])

    def __call__(self, x: np.ndarray) -> np.ndarray:
        s = np.clip(x[self.joints], self._low, self._high)
        return self._interp(s[None, :])[0].reshape(self._shape)


def gain_schedule(
    model, op: OperatingPoint, sched: ScheduleSettings, sample_time: float, Q, R, shape
) -> GainSchedule:
    """The LQR gains (each of ``shape``) at the equilibria of the schedule's grid.

    The joints not scheduled stay at ``op``.
    """
    if max(sched.joints) > model.n_u:
        raise SpecError(
            f"value q{max(sched.joints)} is not a joint of this {model.n_u}-joint arm; "
            f"allowed: q1..q{model.n_u}",
            key="schedule",
        )
    state_lin = Linearizer(model, ("joints",))
    gains = np.empty(tuple(len(g) for g in sched.grid) + tuple(shape))
    for index in itertools.product(*(range(len(g)) for g in sched.grid)):
        q = np.array(op.joints, dtype=float)
        for joint, values, i in zip(sched.joints, sched.grid, index):
            q[joint - 1] = values[i]
        A, B, _C, _D = state_lin.matrices(equilibrium(model, q))
        sysd = discretize(control.ss(A, B, np.eye(A.shape[0]), 0), sample_time)
        gains[index] = lqr_gain(np.asarray(sysd.A), np.asarray(sysd.B), Q, R)[0]
    return GainSchedule(sched.joints, sched.grid, gains)


__all__ = ["GainSchedule", "gain_schedule"]
