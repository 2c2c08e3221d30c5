"""The records of a fidelity choice: the runs made, the choice and its evidence, and the
failure to meet a tolerance (:mod:`flexctrl.fidelity.ladder` describes the method)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flexctrl.errors import FlexctrlError
from flexctrl.sim.tip_error import TipError, tip_error
from flexctrl.spec.fidelity import Fidelity


class ToleranceUnreachable(FlexctrlError):
    """No rung of the ladder meets the tolerance; ``evidence`` holds what was measured."""

    def __init__(self, message: str, evidence: dict[str, Any]):
        super().__init__(message)
        self.evidence = evidence


@dataclass(frozen=True)
class RunRecord:
    """One simulation made while choosing.

    Attributes
    ----------
    fidelity : str
    integrator : str
    dt : float
        Step (s).
    omega_max : float
        The model's ``omega_max`` (rad/s).
    wall_time_s : float
        Integration wall time (s).
    build_time_s : float
        Model build plus integrator setup (compilation or cache load) in this process (s).
    time, tip : numpy.ndarray
        Sample times (s) and tip positions (m).
    diverged_at : float or None
        Time (s) a closed loop diverged (its tip path stops there), None when it did not.
    torque : numpy.ndarray or None
        Joint torques (N m) on ``time`` (closed-loop runs: the controller's), else None.
    """

    fidelity: str
    integrator: str
    dt: float
    omega_max: float
    wall_time_s: float
    build_time_s: float
    time: np.ndarray = field(repr=False)
    tip: np.ndarray = field(repr=False)
    diverged_at: float | None = None
    torque: np.ndarray | None = field(default=None, repr=False)

    def facts(self) -> dict[str, Any]:
        """JSON-ready settings and timings."""
        facts = {
            "fidelity": self.fidelity,
            "integrator": self.integrator,
            "dt_s": self.dt,
            "omega_max_rad_s": self.omega_max,
            "omega_max_dt": self.omega_max * self.dt,
            "wall_time_s": self.wall_time_s,
            "build_time_s": self.build_time_s,
        }
        if self.diverged_at is not None:
            facts["diverged_at_s"] = self.diverged_at
        return facts


@dataclass(frozen=True)
class FidelityChoice:
    """The outcome of :func:`choose_fidelity`.

    Attributes
    ----------
    choice : Fidelity
        The chosen rung (a ``--fidelity`` spelling through ``str``).
    tolerance : float
        Tolerance on the tip position (m).
    estimated_error : float
        ``safety`` times the largest tip distance to the next rung (m): the estimate that justified
        the choice.
    reference_error : float
        Largest tip distance of the choice from the reference (m).
    reference_error_rms : float
        Its root mean square (m).
    cost_ratio : float
        Integration wall time of the choice over that of the reference.
    integrator : str
    dt : float
        Integrator and step (s) the choice is run with.
    evidence : dict
        Everything measured: the bandwidth rule, every rung's run and estimate, the
        reference and its convergence checks (see :meth:`to_dict`).
    """

    choice: Fidelity
    tolerance: float
    estimated_error: float
    reference_error: float
    reference_error_rms: float
    cost_ratio: float
    integrator: str
    dt: float
    evidence: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the four headline keys first, then the evidence."""
        return {
            "choice": str(self.choice),
            "tolerance_m": self.tolerance,
            "estimated_error": self.estimated_error,
            "reference_error": self.reference_error,
            "reference_error_rms": self.reference_error_rms,
            "cost_ratio": self.cost_ratio,
            "integrator": self.integrator,
            "dt_s": self.dt,
            **self.evidence,
        }


def rung_name(n: int) -> str:
    return "rigid" if n == 0 else f"amm:{n}"


def tip_distance(a: RunRecord, b: RunRecord):
    """Tip distance of ``b`` from ``a`` on ``a``'s samples (the finer run goes first); infinite if either diverged."""
    if a.diverged_at is not None or b.diverged_at is not None:
        return TipError(rms=math.inf, max=math.inf)
    first, second = (a, b) if a.dt <= b.dt else (b, a)
    return tip_error(first.time, first.tip, second.time, second.tip)
