"""When a linear MPC must have arrived: the shortest feasible arrival plus a margin (plain data).

:class:`ArrivalSettings` is the ``[arrival]`` table of an MPC controller file; the
algorithm that uses it is :mod:`flexctrl.control.mpc.arrival_search`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from flexctrl.spec.field_checks import choice_field, number_field

ArrivalKind = Literal["none", "minimum_time"]


@dataclass(frozen=True)
class ArrivalSettings:
    """Minimum-time arrival of a linear MPC whose horizon covers the manoeuvre.

    Attributes
    ----------
    kind : {"none", "minimum_time"}
        ``"minimum_time"``: when the controller first sees a target it finds the earliest
        predicted stage from which the arm can stay inside the arrival band, within the
        hard torque limits and the deflection limit (a linear programme per candidate
        stage, bisection), and from then on asks every prediction to be inside the band
        from that absolute time plus ``margin`` (soft rows with the MPC's slack penalty).
    band : float
        m: the arrival band of the tip position error and of each joint's error expressed
        as the tip motion it causes (``|d tip / d q_j| * |q_j - q_j,target|``).
    margin : float
        s, added to the shortest feasible arrival: room for the difference between the
        linear prediction and the arm.
    """

    kind: ArrivalKind = "none"
    band: float = 5e-4
    margin: float = 0.1

    def __post_init__(self) -> None:
        choice_field("kind", self.kind, ArrivalKind)
        number_field("band", self.band, low=0.0, low_open=True, unit="m")
        number_field("margin", self.margin, low=0.0, unit="s")

    @property
    def enabled(self) -> bool:
        """Whether an arrival is planned."""
        return self.kind != "none"


__all__ = ["ArrivalKind", "ArrivalSettings"]
