"""What the automatic-fidelity walk records: its runs, its choice, an unreachable tolerance."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flexctrl.errors import FlexctrlError
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
        The rung (``rigid``, ``amm:N``) or reference model run.
    integrator : str
        The integrator (``rk4``, ``cvodes`` ...; ``linear-rk4`` and ``linear-exact`` for the
        linear estimates).
    dt : float
        Step (s).
    omega_max : float
        The model's ``omega_max`` (rad/s).
    wall_time_s : float
        Integration wall time (s).
    build_time_s : float
        Model build plus integrator setup (compilation or cache load) in this process (s).
    time : numpy.ndarray
        Sample times (s).
    tip : numpy.ndarray
        Tip positions (m), shape (T, 2).
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
        ``safety`` times the largest tip distance to the next rungs (m): the estimate that
        justified the choice.
    reference_error : float
        Largest tip distance of the choice from the reference (m).
    reference_error_rms : float
        Its root mean square (m).
    cost_ratio : float
        Integration wall time of the choice over that of the reference.
    integrator : str
        The integrator the choice is run with.
    dt : float
        Its step (s).
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
