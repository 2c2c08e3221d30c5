"""The largest stable step of an integrator on a model, found by bisection on probe runs.

:func:`largest_stable_step` runs :class:`~flexctrl.analysis.stability.probe.StabilityProbe`
at a sequence of steps:

The search starts at ``omega_max h = 1``, grows the step fourfold while stable (up to a
cap, ``omega_max h = 1000 x 2.785``, :data:`flexctrl.sim.rk4.RK4_STABILITY_LIMIT`) or
shrinks it fourfold while unstable (down to a floor, ``omega_max h = 0.01``), then bisects
geometrically to ``rel_tol``.  The outcome is ``"bracketed"`` (``h_measured`` stable,
``h_unstable`` unstable), ``"stable_at_cap"`` (``h_measured`` = the cap: stable at every
tested step, e.g. Newmark) or ``"unstable_at_floor"`` (``h_measured = 0``: unstable at
every tested step, e.g. explicit Euler on undamped modes; at the floor an undamped mode
grows by ``(omega h)^2/2 = 5e-5`` per step, five times the tolerance, so the floor is
resolvable).  Bisection assumes one boundary (stable below it, unstable above), which
holds for these methods along every ray ``lambda h``, ``h > 0``, met here; a failure that
is not growth (Newton divergence) also ends the stable range and is reported as such
(:attr:`~flexctrl.analysis.stability.probe.Probe.reason`).

The theory the result is compared with (``h_theory``, :attr:`StabilityResult.theory`) is
:mod:`flexctrl.analysis.stability.theory`.

Units: SI throughout (s, rad/s).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

from flexctrl.analysis.stability.probe import Probe, StabilityCriterion, StabilityProbe
from flexctrl.analysis.stability.theory import TheoryLimit
from flexctrl.errors import SpecError
from flexctrl.sim.rk4 import RK4_STABILITY_LIMIT

Outcome = Literal["bracketed", "stable_at_cap", "unstable_at_floor"]


@dataclass(frozen=True)
class StabilityResult:
    """The outcome of :func:`largest_stable_step`.

    Attributes
    ----------
    integrator : str
    h_measured : float
        Largest step found stable (s): the cap for ``"stable_at_cap"``, 0 for
        ``"unstable_at_floor"``.
    h_unstable : float
        Smallest step found unstable (s); inf for ``"stable_at_cap"``.
    outcome : {"bracketed", "stable_at_cap", "unstable_at_floor"}
    omega_max : float
        ``max |lambda|`` of ``A`` at the equilibrium (rad/s).
    h_floor, h_cap : float
        The search range (s).
    theory : TheoryLimit or None
        For rk4, euler and newmark.
    probes : tuple of Probe
        In the order run.
    criterion : StabilityCriterion
    n_modes : int
        Modes excited and watched (one per conjugate pair).
    equilibrium_residual : float
        ``max |f(x0, u0)|`` after refinement.
    settings : dict
        The integrator's settings (from its last probe).
    """

    integrator: str
    h_measured: float
    h_unstable: float
    outcome: Outcome
    omega_max: float
    h_floor: float
    h_cap: float
    theory: TheoryLimit | None
    probes: tuple[Probe, ...]
    criterion: StabilityCriterion
    n_modes: int
    equilibrium_residual: float
    settings: dict[str, Any] = field(default_factory=dict)

    @property
    def first_failure(self) -> Probe | None:
        """The unstable probe at the smallest step (None if every probe was stable)."""
        unstable = [p for p in self.probes if not p.stable]
        return min(unstable, key=lambda p: p.h) if unstable else None

    @property
    def h_theory(self) -> float:
        """The theoretical limit (s), NaN without a theory."""
        return self.theory.h if self.theory is not None else math.nan

    @property
    def ratio(self) -> float:
        """``h_measured / h_theory``; NaN when undefined (no theory, 0/0, inf)."""
        h, t = self.h_measured, self.h_theory
        if not (math.isfinite(h) and math.isfinite(t)) or t <= 0:
            return math.nan
        return h / t

    @property
    def note(self) -> str:
        """One sentence on what was found."""
        w = self.omega_max
        if self.outcome == "stable_at_cap":
            return (
                f"stable at every tested step, up to the cap h = {self.h_cap:.4g} s "
                f"(omega_max h = {w * self.h_cap:.4g}); h_measured is that cap, a lower bound"
            )
        if self.outcome == "unstable_at_floor":
            return (
                f"unstable at every tested step, down to h = {self.h_floor:.4g} s "
                f"(omega_max h = {w * self.h_floor:.4g}); h_measured = 0"
            )
        failure = self.first_failure
        why = {
            "growth": "a mode grows",
            "diverged": "the run diverges",
            "solver": "the method's solver fails",
        }.get(failure.kind if failure else "", "")
        return (
            f"stable at h = {self.h_measured:.6g} s, unstable at {self.h_unstable:.6g} s "
            f"(omega_max h = {w * self.h_measured:.5f}){': ' + why if why else ''}"
        )


def largest_stable_step(
    model,
    integrator: str | type,
    x0: Sequence[float],
    u0: Sequence[float] | None = None,
    *,
    criterion: StabilityCriterion | None = None,
    rel_tol: float = 1e-4,
    omega_h_start: float = 1.0,
    omega_h_floor: float = 0.01,
    omega_h_cap: float = 1000.0 * RK4_STABILITY_LIMIT,
    expansion: float = 4.0,
    integrator_options: Mapping[str, Any] | None = None,
) -> StabilityResult:
    """Largest stable step of ``integrator`` on ``model`` about the equilibrium ``(x0, u0)``, by
    bisection.

    Parameters
    ----------
    model, integrator, x0, u0, criterion, integrator_options
        See :class:`StabilityProbe`.
    rel_tol
        Bisection stops when ``h_unstable / h_stable - 1 <= rel_tol``.
    omega_h_start, omega_h_floor, omega_h_cap
        First step, smallest and largest tested step, as ``omega_max h``.
    expansion
        Factor by which the step grows (or shrinks) until the boundary is bracketed.

    Returns
    -------
    StabilityResult

    Raises
    ------
    SpecError
        For bad arguments, a state that is not an equilibrium, or an unstable equilibrium.
    SimulationError
        If the linearisation has no vibration mode (``omega_max = 0``), so there is no step scale.
    """
    _check_search(rel_tol, omega_h_start, omega_h_floor, omega_h_cap, expansion)
    probe = StabilityProbe(
        model, integrator, x0, u0, criterion=criterion, integrator_options=integrator_options
    )
    omega_max = probe.omega_max
    probes: list[Probe] = []

    def stable(y: float) -> bool:
        p = probe(y / omega_max)
        probes.append(p)
        return p.stable

    y_stable, y_unstable, outcome = _bracket(
        stable, omega_h_start, omega_h_floor, omega_h_cap, expansion
    )
    if outcome == "bracketed":
        y_stable, y_unstable = _bisect(stable, y_stable, y_unstable, rel_tol)
    return StabilityResult(
        integrator=probe.name,
        h_measured=y_stable / omega_max,
        h_unstable=y_unstable / omega_max,
        outcome=outcome,
        omega_max=omega_max,
        h_floor=omega_h_floor / omega_max,
        h_cap=omega_h_cap / omega_max,
        theory=probe.theory(),
        probes=tuple(probes),
        criterion=probe.criterion,
        n_modes=probe.n_modes,
        equilibrium_residual=probe.residual,
        settings=dict(probe.settings),
    )


def _check_search(rel_tol: float, start: float, floor: float, cap: float, expansion: float) -> None:
    if not (isinstance(expansion, (int, float)) and 1.0 < expansion <= 1e3):
        raise SpecError(
            f"expansion = {expansion!r} is not allowed; allowed: a number in (1, 1000]",
            key="expansion",
        )
    if not (0 < rel_tol < 1):
        raise SpecError(
            f"rel_tol = {rel_tol!r} is not allowed; allowed: a number in (0, 1)", key="rel_tol"
        )
    if not (0 < floor <= start <= cap and math.isfinite(cap)):
        raise SpecError(
            f"omega_h_floor = {floor!r}, omega_h_start = {start!r}, omega_h_cap = {cap!r} "
            "are not allowed; allowed: 0 < floor <= start <= cap < inf",
            key="omega_h_start",
        )


def _bracket(
    stable: Callable[[float], bool], start: float, floor: float, cap: float, expansion: float
) -> tuple[float, float, Outcome]:
    """``(stable omega h, unstable omega h, outcome)``: the step grown or shrunk to a boundary.

    ``"stable_at_cap"`` gives ``(cap, inf)``, ``"unstable_at_floor"`` ``(0, floor)``.
    """
    y = start
    if stable(y):
        while y < cap:
            y_next = min(expansion * y, cap)
            if not stable(y_next):
                return y, y_next, "bracketed"
            y = y_next
        return cap, math.inf, "stable_at_cap"
    while y > floor:
        y_next = max(y / expansion, floor)
        if stable(y_next):
            return y_next, y, "bracketed"
        y = y_next
    return 0.0, floor, "unstable_at_floor"


def _bisect(
    stable: Callable[[float], bool], y_stable: float, y_unstable: float, rel_tol: float
) -> tuple[float, float]:
    """The bracket narrowed geometrically until ``y_unstable / y_stable - 1 <= rel_tol``."""
    while y_unstable / y_stable - 1.0 > rel_tol:
        mid = math.sqrt(y_stable * y_unstable)
        if stable(mid):
            y_stable = mid
        else:
            y_unstable = mid
    return y_stable, y_unstable


__all__ = ["Outcome", "StabilityResult", "largest_stable_step"]
