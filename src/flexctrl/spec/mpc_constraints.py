"""Bounds the linear MPC keeps over its horizon, named by signal (plain data and the file table).

A :class:`Bound` names one signal and its lower and upper bound, in SI units in Python:

========== =================================================== ========
signal     what                                                unit
========== =================================================== ========
``q<i>``   joint ``i``'s angle                                 rad
``dq<i>``  joint ``i``'s rate                                  rad/s
``w<i>``   link ``i``'s tip deflection (a link with modes)     m
``tip_x``  the tip's position in the base frame, x and y       m
``tip_y``
``du<i>``  joint ``i``'s torque rate, ``(u_k - u_(k-1)) / Ts`` N m/s
========== =================================================== ========

Joints and links count from 1.  The state bounds hold on every predicted state
``x_1 .. x_N`` (the deflection and tip on their linearisation at the target, as the soft
deflection limit); a hard bound is a constraint of the QP (an infeasible QP takes the
settings' fallback), a soft one has a slack with the MPC's ``slack_l1``/``slack_l2``
penalties, weighed per the bound's own scale.  Torque-rate bounds are always hard: holding
the last torque meets them, so they can never make the QP infeasible; the first one acts
on the change from the torque applied in the sample that just ended.

What holds on the arm: the bounds hold on the QP's linear prediction at the sample instants,
so the arm keeps them to the prediction's one-sample error.  On a rigid arm that error is
small (a 25 deg/s joint-rate bound on the 30 degree quintic move peaks 0.04 % above it).  A
flexible arm's joint rate also carries the hub's vibration against the links, which the
sampled model sees only at the samples (between them it can far exceed a rate bound), and a
moving reference that is not a trajectory of the sampled linear model (the quasi-static
deflection and the held feed-forward of a fast move) shifts every prediction by its own
one-sample mismatch; bound such signals with that margin in mind.

In a controller file the ``[constraints]`` table holds one key per signal with
``[lower, upper]`` (``-inf``/``inf`` for none), angles in degrees under keys that say so,
and ``soft``, the list of soft signals (the rest are hard)::

    [constraints]
    dq1_deg_s = [-40.0, 40.0]   # deg/s
    q2_deg = [-20.0, 20.0]      # deg
    w1 = [-0.02, 0.02]          # m
    tip_y = [0.2, inf]          # m
    du1 = [-3000.0, 3000.0]     # N m/s
    soft = ["w1", "tip_y"]
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from flexctrl.errors import SpecError, keywords_checked

#: The signals a bound may name (joints and links from 1).
SIGNAL_PATTERN = r"q[1-9]\d*|dq[1-9]\d*|w[1-9]\d*|du[1-9]\d*|tip_x|tip_y"
_ALLOWED = "q<i> (rad), dq<i> (rad/s), w<i> (m), tip_x, tip_y (m), du<i> (N m/s)"
_DEG = math.pi / 180.0


@keywords_checked
@dataclass(frozen=True)
class Bound:
    """A bound on one signal of the linear MPC's prediction (:mod:`flexctrl.spec.mpc_constraints`).

    Attributes
    ----------
    signal : str
        ``"q<i>"`` (rad), ``"dq<i>"`` (rad/s), ``"w<i>"`` (m), ``"tip_x"``, ``"tip_y"``
        (m) or ``"du<i>"`` (N m/s); joints and links from 1.
    lower, upper : float
        The bounds in the signal's unit; ``-inf``/``inf`` for none (not both).
    soft : bool
        With a slack (penalised by the MPC's ``slack_l1``, ``slack_l2``) instead of a hard
        constraint.  Torque-rate bounds are always hard.
    """

    signal: str
    lower: float = -math.inf
    upper: float = math.inf
    soft: bool = False

    def __post_init__(self) -> None:
        key = f"constraints.{self.signal}"
        if not isinstance(self.signal, str) or not re.fullmatch(SIGNAL_PATTERN, self.signal):
            raise SpecError(
                f"value {self.signal!r} is not a signal; allowed: {_ALLOWED}", key="constraints"
            )
        for name in ("lower", "upper"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value):
                raise SpecError(f"{name} {value!r} is not a number", key=key)
            object.__setattr__(self, name, float(value))
        if not self.lower < self.upper or (math.isinf(self.lower) and math.isinf(self.upper)):
            raise SpecError(
                f"bounds [{self.lower:g}, {self.upper:g}] are not allowed; allowed: lower < "
                "upper, at least one finite",
                key=key,
            )
        if not isinstance(self.soft, bool):
            raise SpecError(f"soft {self.soft!r} is not true or false", key=key)
        if self.soft and self.signal.startswith("du"):
            raise SpecError(
                "a torque-rate bound is always hard (holding the torque meets it); allowed: "
                "soft = false",
                key=key,
            )

    @property
    def kind(self) -> str:
        """``"q"``, ``"dq"``, ``"w"``, ``"du"`` or ``"tip"``."""
        return "tip" if self.signal.startswith("tip") else self.signal.rstrip("0123456789")

    @property
    def index(self) -> int:
        """The joint or link, 0-based; the tip's component (x 0, y 1)."""
        if self.kind == "tip":
            return 0 if self.signal == "tip_x" else 1
        return int(self.signal[len(self.kind) :]) - 1


def checked_bounds(value) -> tuple[Bound, ...]:
    """``value`` (a sequence of :class:`Bound`) as a tuple, each signal once.

    Raises
    ------
    SpecError
        For an entry that is not a :class:`Bound` or a signal named twice.
    """
    if isinstance(value, Bound) or not isinstance(value, (tuple, list)):
        raise SpecError(
            f"value of type {type(value).__name__} is not allowed; allowed: a list of "
            "flexctrl.Bound(signal, lower, upper, soft=...)",
            key="constraints",
        )
    seen: set[str] = set()
    for i, bound in enumerate(value):
        if not isinstance(bound, Bound):
            raise SpecError(
                f"entry {i} ({bound!r}) is not a flexctrl.Bound", key=f"constraints[{i}]"
            )
        if bound.signal in seen:
            raise SpecError(f"signal {bound.signal!r} is bounded twice", key="constraints")
        seen.add(bound.signal)
    return tuple(value)


#: ``(file key pattern, signal prefix, unit, factor to SI)``.
_FILE_KEYS = (
    (r"q([1-9]\d*)_deg", "q", "deg", _DEG),
    (r"dq([1-9]\d*)_deg_s", "dq", "deg/s", _DEG),
    (r"w([1-9]\d*)", "w", "m", 1.0),
    (r"du([1-9]\d*)", "du", "N m/s", 1.0),
    (r"tip_(x|y)", "tip_", "m", 1.0),
)


def _file_bound(reader, key: str, soft: set[str]) -> Bound:
    found = None
    for pattern, prefix, unit, factor in _FILE_KEYS:
        match = re.fullmatch(pattern, key)
        if match is not None:
            found = (prefix + match.group(1), unit, factor)
            break
    if found is None:
        plain = re.fullmatch(r"(d?q)([1-9]\d*)", key)
        hint = f" (angles carry their unit: '{key}_deg{'_s' if key.startswith('dq') else ''}')"
        raise reader.error(
            key,
            "unknown key" + (hint if plain else "") + "; allowed: q<i>_deg, dq<i>_deg_s, w<i>, "
            "tip_x, tip_y, du<i> (each [lower, upper]) and soft",
        )
    signal, unit, factor = found
    pair = reader.raw(key)
    if (
        not isinstance(pair, list)
        or len(pair) != 2
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in pair)
    ):
        raise reader.error(key, f"value {pair!r} is not allowed; allowed: [lower, upper] in {unit}")
    try:
        return Bound(signal, pair[0] * factor, pair[1] * factor, soft=signal in soft)
    except SpecError as exc:
        raise reader.error(key, str(exc).split(": ", 1)[-1] + f" ({unit} in files)") from None


def read_constraints(reader) -> tuple[Bound, ...]:
    """The ``[constraints]`` table of an MPC file (module docstring) as bounds; () without it."""
    if not reader.has("constraints"):
        return ()
    r = reader.table_of("constraints")
    soft_list = r.raw("soft", [])
    if not isinstance(soft_list, list) or not all(isinstance(s, str) for s in soft_list):
        raise r.error("soft", f"value {soft_list!r} is not allowed; allowed: a list of signals")
    bounds = [_file_bound(r, key, set(soft_list)) for key in list(r.table) if key != "soft"]
    unknown = set(soft_list) - {b.signal for b in bounds}
    if unknown:
        raise r.error(
            "soft",
            f"value {sorted(unknown)!r} names signals without bounds; allowed: "
            f"{sorted(b.signal for b in bounds)}",
        )
    r.finish()
    return tuple(bounds)


__all__ = ["Bound", "SIGNAL_PATTERN", "checked_bounds", "read_constraints"]
