"""Joint references as plain data: a point-to-point path from one set of joint angles to another.

:class:`JointReference` is the joint path ``q_ref(t)`` from ``q_start`` to ``q_target``
(rad), either a step at ``t_start`` or a quintic over ``move_time`` (s)::

    q_ref(t) = q_start + (q_target - q_start) s(tau),   tau = clip((t - t_start) / move_time, 0, 1)
    s(tau)   = 10 tau^3 - 15 tau^4 + 6 tau^5

the minimum-jerk point-to-point path: zero velocity and acceleration at both ends,
peak velocity ``1.875 dq / T`` at mid-move, peak acceleration ``5.774 dq / T^2`` at
``tau = 0.211`` and ``0.789``.  The deflections and torques that go with it on a model
are :class:`flexctrl.control.reference_trajectory.ReferenceTrajectory`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from flexctrl.errors import SpecError, keywords_checked
from flexctrl.spec.units import warn_if_degrees

Profile = Literal["step", "quintic"]
DeflectionReference = Literal["quasi_static", "static"]
PROFILES: tuple[str, ...] = get_args(Profile)
DEFLECTIONS: tuple[str, ...] = get_args(DeflectionReference)


@dataclass(frozen=True)
class JointReference:
    """A point-to-point joint path (see the module docstring).

    Attributes
    ----------
    q_start, q_target : tuple of float
        Joint angles, rad.
    profile : {"step", "quintic"}
    move_time : float
        Duration of the quintic, s (> 0; ignored by the step).
    t_start : float
        Time the move starts, s.
    """

    q_start: tuple[float, ...]
    q_target: tuple[float, ...]
    profile: str = "step"
    move_time: float = 0.0
    t_start: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "q_start", tuple(float(a) for a in self.q_start))
        object.__setattr__(self, "q_target", tuple(float(a) for a in self.q_target))
        if self.profile not in PROFILES:
            raise SpecError(
                f"value {self.profile!r} is not allowed; allowed: {', '.join(map(repr, PROFILES))}",
                key="profile",
            )
        if len(self.q_start) != len(self.q_target):
            raise SpecError(
                f"q_start has {len(self.q_start)} angles and q_target {len(self.q_target)}; "
                "allowed: one per joint in both",
                key="q_target",
            )
        if self.profile == "quintic" and not (math.isfinite(self.move_time) and self.move_time > 0):
            raise SpecError(
                f"value {self.move_time!r} is not allowed; allowed: a move time > 0 s for the "
                "quintic",
                key="move_time",
            )
        if not (math.isfinite(self.t_start) and self.t_start >= 0):
            raise SpecError(
                f"value {self.t_start!r} is not allowed; allowed: a start time >= 0 s",
                key="t_start",
            )

    @property
    def t_arrive(self) -> float:
        """Time (s) at which the reference reaches the target: the end of the move."""
        return self.t_start + (self.move_time if self.profile == "quintic" else 0.0)

    def derivatives(self, t, order: int = 2) -> tuple[np.ndarray, ...]:
        """``(q, qd, qdd[, qddd])`` at the times ``t`` (s), up to ``order`` (<= 3).

        Arrays (T, n) in rad, rad/s, rad/s^2, rad/s^3.
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        q0, q1 = np.asarray(self.q_start), np.asarray(self.q_target)
        delta = q1 - q0
        if self.profile == "step":
            s = (t >= self.t_start).astype(float)
            out = [q0[None, :] + s[:, None] * delta[None, :]]
            out += [np.zeros((t.size, delta.size)) for _ in range(order)]
            return tuple(out)
        T = self.move_time
        tau = np.clip((t - self.t_start) / T, 0.0, 1.0)
        inside = ((t > self.t_start) & (t < self.t_start + T)).astype(float)
        s = tau**3 * (10 - 15 * tau + 6 * tau**2)
        ds = inside * 30 * tau**2 * (1 - tau) ** 2 / T
        dds = inside * 60 * tau * (1 - tau) * (1 - 2 * tau) / T**2
        ddds = inside * 60 * (1 - 6 * tau + 6 * tau**2) / T**3
        factors = (s, ds, dds, ddds)[: order + 1]
        return tuple(
            q0[None, :] * (k == 0) + f[:, None] * delta[None, :] for k, f in enumerate(factors)
        )

    def joints(self, t) -> np.ndarray:
        """Joint angles (T, n), rad, at the times ``t`` (s)."""
        return self.derivatives(t, order=0)[0]

    def settings(self) -> dict:
        """Plain data (angles in degrees)."""
        return {
            "profile": self.profile,
            "move_time_s": self.move_time,
            "t_start_s": self.t_start,
            "q_start_deg": [math.degrees(a) for a in self.q_start],
            "q_target_deg": [math.degrees(a) for a in self.q_target],
            "t_arrive_s": self.t_arrive,
        }


@keywords_checked
@dataclass(frozen=True)
class Move:
    """A joint move for :func:`flexctrl.closed_loop` from ``start`` to ``target`` (rad).

    A quintic by default.

    Parameters
    ----------
    start, target : sequence of float
        Joint angles, rad (one per joint).
    time : float
        Duration of the quintic, s (> 0; unused by a step).
    profile : {"quintic", "step"}
        ``"quintic"``: the minimum-jerk path of :class:`JointReference`; ``"step"``: the
        reference jumps to the target at ``t_start``.
    t_start : float
        When the move starts, s.
    deflection : {"quasi_static", "static"}
        The elastic part of the reference the model-based controllers track
        (:class:`flexctrl.control.reference_trajectory.ReferenceTrajectory`).

    Examples
    --------
    >>> import numpy as np
    >>> move = Move(start=np.radians([0, 0, 0]), target=np.radians([30, 0, 0]), time=1.5)
    >>> move.t_arrive
    1.5
    >>> [round(float(a), 4) for a in move.joint_reference().joints([0.75])[0]]
    [0.2618, 0.0, 0.0]
    """

    start: tuple[float, ...]
    target: tuple[float, ...]
    time: float = 0.0
    profile: str = "quintic"
    t_start: float = 0.0
    deflection: str = "quasi_static"

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", _angles(self.start, "start"))
        object.__setattr__(self, "target", _angles(self.target, "target"))
        if self.deflection not in DEFLECTIONS:
            raise SpecError(
                f"value {self.deflection!r} is not allowed; allowed: "
                f"{', '.join(map(repr, DEFLECTIONS))}",
                key="deflection",
            )
        self.joint_reference()  # validates profile, lengths and times

    def joint_reference(self) -> JointReference:
        """The joint path as a :class:`JointReference` (rad, s)."""
        return JointReference(
            self.start, self.target, self.profile, float(self.time), float(self.t_start)
        )

    @property
    def t_arrive(self) -> float:
        """Time (s) the reference reaches the target."""
        return self.joint_reference().t_arrive


@dataclass(frozen=True)
class JointSequence:
    """Point-to-point joint paths one after the other (each a :class:`JointReference`).

    The same interface as :class:`JointReference`: ``q_start`` is the first path's start,
    ``q_target`` the last one's target, ``t_arrive`` the last one's arrival, and the joint
    angles are the first start plus every path's travel so far.

    Attributes
    ----------
    legs : tuple of JointReference
        Each starts where the previous ends, at or after its arrival.
    """

    legs: tuple[JointReference, ...]

    def __post_init__(self) -> None:
        if not self.legs:
            raise SpecError("no moves; allowed: one or more", key="moves")
        for i, (a, b) in enumerate(zip(self.legs, self.legs[1:]), 2):
            if not np.allclose(a.q_target, b.q_start, atol=1e-12):
                raise SpecError(
                    f"move {i} starts at {np.degrees(b.q_start).round(6).tolist()} deg, not where "
                    f"move {i - 1} ends; allowed: consecutive moves",
                    key="moves",
                )
            if b.t_start < a.t_arrive - 1e-12:
                raise SpecError(
                    f"move {i} starts at {b.t_start:g} s, before move {i - 1} arrives at "
                    f"{a.t_arrive:g} s; allowed: one move at a time",
                    key="moves",
                )

    @property
    def q_start(self) -> tuple[float, ...]:
        """The first move's start, rad."""
        return self.legs[0].q_start

    @property
    def q_target(self) -> tuple[float, ...]:
        """The last move's target, rad."""
        return self.legs[-1].q_target

    @property
    def t_start(self) -> float:
        """The first move's start, s."""
        return self.legs[0].t_start

    @property
    def t_arrive(self) -> float:
        """The last move's arrival, s."""
        return self.legs[-1].t_arrive

    def derivatives(self, t, order: int = 2) -> tuple[np.ndarray, ...]:
        """``(q, qd, qdd[, qddd])`` at the times ``t`` (s), as in :class:`JointReference`."""
        parts = [leg.derivatives(t, order) for leg in self.legs]
        out = [np.sum([p[k] for p in parts], axis=0) for k in range(order + 1)]
        starts = [np.asarray(leg.q_start, dtype=float) for leg in self.legs[1:]]
        if starts:
            out[0] = out[0] - np.sum(starts, axis=0)
        return tuple(out)

    def joints(self, t) -> np.ndarray:
        """Joint angles (T, n), rad, at the times ``t`` (s)."""
        return self.derivatives(t, order=0)[0]

    def settings(self) -> dict:
        """Plain data (angles in degrees): one entry per move."""
        return {"moves": [leg.settings() for leg in self.legs], "t_arrive_s": self.t_arrive}


@keywords_checked
@dataclass(frozen=True)
class MoveSequence:
    """Moves one after the other for :func:`flexctrl.closed_loop` (e.g. out and back).

    Parameters
    ----------
    moves : tuple of Move
        Each starts where the previous ends, at or after its arrival (its own ``t_start``).

    Examples
    --------
    >>> import numpy as np
    >>> out = Move(np.radians([0, 0, 0]), np.radians([30, 0, 0]), time=1.5)
    >>> back = Move(np.radians([30, 0, 0]), np.radians([0, 0, 0]), time=1.5, t_start=4.0)
    >>> both = MoveSequence((out, back))
    >>> q = both.joint_reference().joints([3.0])[0]
    >>> both.t_arrive, [round(float(np.degrees(a)), 3) for a in q]
    (5.5, [30.0, 0.0, 0.0])
    """

    moves: tuple[Move, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "moves", tuple(self.moves))
        self.joint_reference()

    @property
    def deflection(self) -> str:
        """The first move's deflection reference."""
        return self.moves[0].deflection

    def joint_reference(self) -> JointSequence:
        """The joint paths as a :class:`JointSequence` (rad, s)."""
        return JointSequence(tuple(m.joint_reference() for m in self.moves))

    @property
    def t_arrive(self) -> float:
        """Time (s) the last move arrives."""
        return self.joint_reference().t_arrive


def _angles(values, key: str) -> tuple[float, ...]:
    try:
        angles = tuple(float(a) for a in np.atleast_1d(np.asarray(values, dtype=float)))
    except (TypeError, ValueError):
        raise SpecError(
            f"value {values!r} is not a list of numbers; allowed: joint angles in rad", key=key
        ) from None
    if not all(math.isfinite(a) for a in angles):
        raise SpecError(
            f"value {list(angles)!r} is not finite; allowed: finite joint angles in rad", key=key
        )
    warn_if_degrees(angles, key=key)
    return angles
