"""The largest stable step of an integrator on a model, measured by bisection.

Measured: :func:`largest_stable_step` (probes: :class:`StabilityProbe`)
    The model is linearised at an equilibrium ``(x0, u0)`` (joints held by the
    constant torques ``u0``, free to move; :func:`flexctrl.linear.equilibrium`
    makes one), ``A = df/dx``.  Its eigenvectors give *modal amplitudes*
    ``c_i = w_i^H (x - x0) / (w_i^H v_i)`` (``v_i``, ``w_i`` right and left
    eigenvectors).  A probe at step ``h`` runs the *real* integrator (compiled
    RK4 or Euler, Newmark, ...) on the full nonlinear model, holding ``u0``, for
    ``steps`` steps (1000) twice: from ``x0 + d`` and from ``x0 - d``, where ``d``
    displaces every vibration mode at once (the sum of the real parts of the
    eigenvectors, each scaled to a largest coordinate of 1, the sum to a largest
    coordinate of ``amplitude``: 1e-9 m or rad by default).  The modal amplitudes
    of half the difference of the two runs are watched.  The probe is

    * **unstable** if, at any step, some watched mode's amplitude exceeds
      ``growth`` (1.01) times its initial value, or a run fails (non-finite
      state, the energy check of :mod:`flexctrl.sim.divergence`, Newton
      divergence in an implicit step);
    * **stable** otherwise.

    Why this criterion is sharp.  In the linear regime each modal amplitude is
    multiplied by exactly ``|R(lambda_i h)|`` per step (``R`` the method's
    amplification factor), with no oscillation and no transient growth (the
    modal coordinates decouple the motion; a state norm would mix modes and
    beat).  So the probe is unstable exactly when ``max_i |R(lambda_i h)|``
    exceeds ``growth^(1/steps)``: a per-step growth rate tolerance of
    ``ln(1.01)/1000 = 1.0e-5``.  Just above the boundary ``h*`` the growth rate
    is ``ln|R| ~ s e`` for a relative excess ``e = h/h* - 1``, with slope
    ``s = d ln|R| / d ln h``; the probe resolves the boundary to ``e = 1e-5/s``.
    Classical RK4 on an undamped mode (``|R(iy)|^2 = 1 - y^6/72 + y^8/576``)
    has ``s = 7.1`` at ``y = 2 sqrt 2``: the boundary is found to 1.4e-6
    relative, and :func:`largest_stable_step` stops bisecting at ``rel_tol =
    1e-4``.  Explicit Euler on a mode with damping ratio ``zeta`` has ``s = 2
    zeta^2`` at its limit ``omega h = 2 zeta``: 5e-4 relative for ``zeta = 0.1``
    but 5 % for ``zeta = 0.01`` (a soft boundary).  A state norm with a
    threshold of, say, 10x over 100 steps would resolve RK4's boundary to only
    ``ln 10 / (100 s) = 0.3 %``, and the beating of undamped modes in a state
    norm would need a far larger threshold.

    Why two runs, and why 1e-9.  Quadratic terms (centrifugal, Coriolis, the
    configuration dependence of ``M``; in finite-element models fast modes
    with tiny amplitude have large accelerations) force the coordinates with a
    term even in ``d``; at long steps it drives slow, nearly free joint modes
    and drifts, and disturbed single-run amplitudes in proportion to the
    amplitude (fem:2, Newmark at ``omega_max h = 256``: growth 1 + 0.14 at
    1e-8, 1 + 0.014 at 1e-9).  Half the difference of the ``+d`` and ``-d`` runs
    cancels every even-order term (and the equilibrium's remaining offset),
    leaving relative errors of order ``amplitude^2`` (there: 1 + 2.6e-5 at
    1e-9).  Smaller amplitudes meet rounding: Newmark's accelerations come from
    position differences over ``h^2``; at 1e-9 the noise stays below 2e-3 on
    every model of the study.  Only modes with ``|lambda| h >= sqrt(2 growth
    rate tolerance)`` are watched (:meth:`StabilityProbe.watched`): a slower
    mode cannot grow faster than the tolerance under these methods, and its
    rounding noise would otherwise decide the verdict at small steps.

    The search starts at ``omega_max h = 1``, grows the step fourfold while stable
    (up to a cap, ``omega_max h = 1000 x 2.785``, :data:`flexctrl.sim.rk4.RK4_STABILITY_LIMIT`) or
    shrinks it fourfold while unstable (down to a floor, ``omega_max h = 0.01``), then bisects
    geometrically to ``rel_tol``.  The outcome is ``"bracketed"`` (``h_measured`` stable,
    ``h_unstable`` unstable), ``"stable_at_cap"`` (``h_measured`` = the cap: stable at every tested
    step, e.g. Newmark) or ``"unstable_at_floor"`` (``h_measured = 0``: unstable at every tested
    step, e.g. explicit Euler on undamped modes; at the floor an undamped mode grows by ``(omega
    h)^2/2 = 5e-5`` per step, five times the tolerance, so the floor is resolvable).  Bisection
    assumes one boundary (stable below it, unstable above), which holds for these methods along
    every ray ``lambda h``, ``h > 0``, met here; a failure that is not growth (Newton divergence)
    also ends the stable range and is reported as such (:attr:`Probe.reason`).

The theory it is compared with (``h_theory``, :attr:`StabilityResult.theory`) is
:mod:`flexctrl.analysis.stability.theory`.

Units: SI throughout (s, rad/s; amplitudes in m or rad).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import casadi as ca
import numpy as np
import scipy.linalg

from flexctrl.analysis.stability.theory import (
    EIGENVALUE_TOL,
    THEORY_METHODS,
    TheoryLimit,
    classify_eigenvalues,
    theoretical_step_limit,
)
from flexctrl.dynamics.jacobians import jacobian_function
from flexctrl.dynamics.parametric import try_expand
from flexctrl.errors import SimulationError, SolverError, SpecError
from flexctrl.sim.rk4 import RK4_STABILITY_LIMIT

Outcome = Literal["bracketed", "stable_at_cap", "unstable_at_floor"]


# -- linearisation --------------------------------------------------------------------


def linearization_function(model) -> ca.Function:
    """``(x, u) -> (f, A = df/dx)`` of the model's forward dynamics (free joints, torques held),
    expanded to SX.

    :func:`flexctrl.dynamics.jacobians.jacobian_function`, the one Jacobian builder.
    """
    return try_expand(jacobian_function(model, value=True))


def linearize(
    model, x0: np.ndarray, u0: np.ndarray, function: ca.Function | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(f(x0, u0), A = df/dx(x0, u0))``; pass ``function`` (:func:`linearisation_function`) to reuse it."""
    f, A = (function or linearization_function(model))(x0, u0)
    return np.asarray(f, dtype=float).ravel(), np.asarray(A, dtype=float)


# -- measurement ----------------------------------------------------------------------


@dataclass(frozen=True)
class StabilityCriterion:
    """When a probe run counts as stable (see the module docstring).

    Parameters
    ----------
    steps
        Steps per probe run.
    growth
        A probe is unstable when a modal amplitude exceeds ``growth`` times its
        initial value (> 1).
    amplitude
        Largest coordinate of the initial displacement (m or rad; linear regime).
    """

    steps: int = 1000
    growth: float = 1.01
    amplitude: float = 1e-9

    def __post_init__(self) -> None:
        if (
            isinstance(self.steps, bool)
            or not isinstance(self.steps, int)
            or not 10 <= self.steps <= 10_000_000
        ):
            raise SpecError(
                f"steps = {self.steps!r} is not allowed; allowed: an integer in [10, 1e7]",
                key="steps",
            )
        if (
            isinstance(self.growth, bool)
            or not isinstance(self.growth, (int, float))
            or not 1.0 < self.growth <= 1e6
        ):
            raise SpecError(
                f"growth = {self.growth!r} is not allowed; allowed: a number in (1, 1e6]",
                key="growth",
            )
        if (
            isinstance(self.amplitude, bool)
            or not isinstance(self.amplitude, (int, float))
            or not 0.0 < self.amplitude <= 0.1
        ):
            raise SpecError(
                f"amplitude = {self.amplitude!r} is not allowed; allowed: a number in (0, 0.1] "
                "(m or rad)",
                key="amplitude",
            )

    @property
    def rate_tolerance(self) -> float:
        """Largest per-step growth rate ``ln|R|`` a stable probe can hide: ``ln(growth)/steps``."""
        return math.log(self.growth) / self.steps


@dataclass(frozen=True)
class Probe:
    """One probe run.

    Attributes
    ----------
    h : float
        Step (s).
    stable : bool
    growth : float
        Largest modal amplitude ratio seen (inf when the run diverged).
    reason : str
        Why the run stopped early (the error), or ``""``.
    kind : {"", "growth", "diverged", "solver"}
        Why it is unstable: a watched amplitude grew, the run diverged
        (:class:`~flexctrl.errors.SimulationError`), or a solver inside the
        method failed (:class:`~flexctrl.errors.SolverError`, e.g. Newton);
        ``""`` when stable.
    """

    h: float
    stable: bool
    growth: float
    reason: str = ""
    kind: str = ""


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


def refine_equilibrium(
    model,
    x0: np.ndarray,
    u0: np.ndarray,
    *,
    tolerance: float,
    max_iterations: int = 8,
    function: ca.Function | None = None,
) -> tuple[np.ndarray, float]:
    """Newton on ``f(x, u0) = 0`` from ``x0`` (least squares where ``A`` is singular); returns ``(x,
    max|f|)``.

    Parameters
    ----------
    tolerance
        Largest acceptable remaining Newton step (m or rad): the offset of the
        true equilibrium from the returned state, in the linear model.

    Raises
    ------
    SpecError
        If ``x0`` is not near an equilibrium: Newton moves it by more than 1 %
        of ``1 + max|x0|`` or cannot bring the step below ``tolerance``.
    """
    function = function or linearization_function(model)
    x = np.array(x0, dtype=float)
    f, A = linearize(model, x, u0, function)
    start = float(np.max(np.abs(f), initial=0.0))
    step_size = math.inf
    for _ in range(max_iterations):
        step = np.linalg.lstsq(A, -f, rcond=None)[0]
        step_size = float(np.max(np.abs(step), initial=0.0))
        if step_size <= 1e-3 * tolerance:
            break
        x = x + step
        f, A = linearize(model, x, u0, function)
    residual = float(np.max(np.abs(f), initial=0.0))
    moved = float(np.max(np.abs(x - x0)))
    if moved > 1e-2 * (1.0 + float(np.max(np.abs(x0)))) or step_size > tolerance:
        raise SpecError(
            f"the state is not an equilibrium: max |f(x0, u0)| = {start:.3g}; Newton moved it by "
            f"{moved:.3g} "
            f"and its last step is {step_size:.3g} (allowed: {tolerance:.3g}); allowed: a static "
            "equilibrium "
            "with its holding torques, e.g. flexctrl.linear.equilibrium(model, q_joints)",
            key="x0",
        )
    return x, residual


@functools.lru_cache(maxsize=8)
def _quiet_class(cls: type) -> type:
    """``cls`` with a one-line divergence message (its advice computes a Jacobian: seconds for big models)."""

    def stability_advice(self, states=()) -> str:
        return "(stability probe)"

    return type(
        f"{cls.__name__}Probe",
        (cls,),
        {"stability_advice": stability_advice, "__module__": __name__},
    )


def _modal_basis(A: np.ndarray, n_q: int, tol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Watched eigenvalues, their normalised right eigenvectors (columns) and modal projection rows."""
    lam, left, right = scipy.linalg.eig(A, left=True, right=True)
    kind, _snapped, _w = classify_eigenvalues(lam, tol)
    keep = [i for i in range(lam.size) if kind[i] in ("undamped", "damped") and lam[i].imag >= 0]
    vectors, rows = [], []
    for i in keep:
        v = right[:, i]
        k = int(np.argmax(np.abs(v[:n_q])))
        v = v / v[k]  # largest coordinate = 1 (real)
        w = left[:, i]
        rows.append(w.conj() / (w.conj() @ v))
        vectors.append(v)
    return lam[keep], np.array(vectors).T, np.array(rows)


class StabilityProbe:
    """Probe runs of one integrator about one equilibrium (module docstring); call it with a step.

    Building it refines the equilibrium, linearises there, checks that no mode
    grows physically, and forms the initial displacement and the modal
    projection; every call ``probe(h)`` then runs the integrator once.

    Parameters
    ----------
    model
        A :class:`~flexctrl.dynamics.model.Model`.
    integrator
        A name of :data:`flexctrl.sim.INTEGRATORS` or an Integrator subclass.
    x0
        Equilibrium state ``(q, qd)`` (rad, m; qd = 0), refined by Newton first.
    u0
        Joint torques holding it (N m); zeros by default.
    criterion
        When a probe counts as stable.
    integrator_options
        Passed to the integrator (``compile``, ``cache_dir``, ``alpha``, ``delta``, ...;
        not ``chunk`` or ``u_function``, which the probe sets).

    Attributes
    ----------
    x_eq : ndarray
        The refined equilibrium.
    eigenvalues : ndarray
        Of ``A = df/dx`` there (rad/s).
    omega_max : float
        ``max |lambda|`` (rad/s).
    n_modes : int
        Modes excited and watched (one per conjugate pair).
    residual : float
        ``max |f(x_eq, u0)|``.

    Raises
    ------
    SpecError
        For bad arguments, a state that is not an equilibrium, or an unstable equilibrium.
    SimulationError
        If the linearisation has no vibration mode (``omega_max = 0``).

    Examples
    --------
    >>> import flexctrl as fc
    >>> from flexctrl.linear import equilibrium
    >>> model = fc.load_model("subedi3link", fidelity="amm:1", gravity=[0.0, 0.0])
    >>> op = equilibrium(model, [0.3, -0.2, 0.1])
    >>> probe = StabilityProbe(model, "rk4", op.x, op.u, integrator_options={"compile": False})
    >>> probe(2.7 / probe.omega_max).stable, probe(2.9 / probe.omega_max).stable
    (True, False)
    """

    def __init__(
        self,
        model,
        integrator: str | type,
        x0: Sequence[float],
        u0: Sequence[float] | None = None,
        *,
        criterion: StabilityCriterion | None = None,
        integrator_options: Mapping[str, Any] | None = None,
    ):
        from flexctrl.sim import get_integrator

        self.model = model
        self.criterion = criterion or StabilityCriterion()
        self.cls = get_integrator(integrator)
        self.options = dict(integrator_options or {})
        for key in ("chunk", "u_function"):
            if key in self.options:
                raise SpecError(
                    f"integrator option '{key}' is set by the probe; allowed: other options of {self.cls.name}",
                    key=key,
                )
        x0 = np.asarray(x0, dtype=float).ravel()
        u0 = np.zeros(model.n_u) if u0 is None else np.asarray(u0, dtype=float).ravel()
        if (
            x0.shape != (model.n_x,)
            or u0.shape != (model.n_u,)
            or not (np.all(np.isfinite(x0)) and np.all(np.isfinite(u0)))
        ):
            raise SpecError(
                f"x0 has shape {x0.shape}, u0 {u0.shape}; expected {model.n_x} and {model.n_u} "
                "finite values",
                key="x0",
            )
        self.u0 = u0
        function = linearization_function(model)
        self.x_eq, self.residual = refine_equilibrium(
            model, x0, u0, tolerance=1e-2 * self.criterion.amplitude, function=function
        )
        _f, A = linearize(model, self.x_eq, u0, function)
        self.eigenvalues = np.linalg.eigvals(A)
        self.omega_max = float(np.max(np.abs(self.eigenvalues), initial=0.0))
        if not self.omega_max > 0:
            raise SimulationError(
                f"the linearisation of '{model.name}' at this state has no vibration mode "
                "(omega_max = 0), "
                "so there is no step scale to search; use a flexible fidelity or a configuration "
                "under load"
            )
        kind, _snapped, _w = classify_eigenvalues(self.eigenvalues)
        if np.any(kind == "growing"):
            rates = np.sort(self.eigenvalues.real[kind == "growing"])[::-1]
            raise SpecError(
                f"the equilibrium is unstable: {rates.size} eigenvalues of df/dx grow physically "
                "(rates up to "
                f"{rates[0]:.4g} 1/s), and over a probe they would swamp the modes being "
                "watched; allowed: a "
                "stable equilibrium (e.g. hanging, or joints held where gravity does not tip the "
                "arm over)",
                key="x0",
            )
        lam, vectors, rows = _modal_basis(A, model.n_q, EIGENVALUE_TOL)
        if rows.size == 0:
            raise SimulationError(
                f"the linearisation of '{model.name}' has no mode that is neither zero nor "
                "growing; nothing to probe"
            )
        shape = vectors.real.sum(axis=1)
        self.d0 = self.criterion.amplitude * shape / np.max(np.abs(shape[: model.n_q]))
        c0 = np.abs(rows @ self.d0)
        usable = c0 > 1e-6 * np.max(c0)  # a mode the sum of shapes cancels (rare) cannot be watched
        self._rows, self._c0, self._speed = rows[usable], c0[usable], np.abs(lam[usable])
        self.n_modes = int(usable.sum())
        # The remaining offset of the equilibrium, per mode, against the mode's initial amplitude.
        offset = np.linalg.lstsq(A, -_f, rcond=None)[0]
        self.offset = float(np.max(np.abs(self._rows @ offset) / self._c0))
        if self.offset > 1e-3:
            raise SpecError(
                "the equilibrium is not accurate enough for a probe of amplitude "
                f"{self.criterion.amplitude:g}: "
                f"its remaining offset is {self.offset:.3g} of a mode's initial amplitude (max "
                "|f| = "
                f"{self.residual:.3g}); allowed: at most 1e-3 (a larger amplitude, or a better equilibrium)",
                key="x0",
            )
        self.settings: dict[str, Any] = {}

    def watched(self, h: float) -> np.ndarray:
        """Which modes a probe at step ``h`` watches: those with ``|lambda| h >= sqrt(2
        rate_tolerance)``.

        A slower mode cannot grow faster than the tolerance under rk4, euler or
        newmark (``|R(z)| <= 1 + |z|^2 / 2`` for small ``z`` in the closed left
        half-plane), so its verdict is "stable" whatever it shows; leaving it
        out keeps rounding noise out of the verdict (Newmark's accelerations
        come from position differences over ``h^2``, so a mode with ``|lambda| h``
        of 1e-7 carries relative noise of order 1e-2 per step).
        """
        return self._speed * h >= math.sqrt(2.0 * self.criterion.rate_tolerance)

    @property
    def name(self) -> str:
        """The integrator's name."""
        return self.cls.name

    def theory(self) -> TheoryLimit | None:
        """:func:`theoretical_step_limit` for this integrator (None without a theory)."""
        if self.cls.name not in THEORY_METHODS:
            return None
        return theoretical_step_limit(
            self.eigenvalues,
            self.cls.name,
            alpha=float(self.options.get("alpha", 0.25)),
            delta=float(self.options.get("delta", 0.5)),
        )

    def amplitudes(self, states: np.ndarray, h: float | None = None) -> np.ndarray:
        """Modal amplitudes of state rows relative to their initial values (rows: samples; columns:
        the
        modes watched at step ``h``, or every excited mode)."""
        keep = slice(None) if h is None else self.watched(h)
        return (
            np.abs((np.asarray(states, dtype=float) - self.x_eq) @ self._rows[keep].T)
            / self._c0[keep]
        )

    def __call__(self, h: float) -> Probe:
        """Run ``criterion.steps`` steps of length ``h`` (s) and classify (module docstring)."""
        if (
            isinstance(h, bool)
            or not isinstance(h, (int, float))
            or not (math.isfinite(h) and h > 0)
        ):
            raise SpecError(
                f"step h = {h!r} is not allowed; allowed: a finite number > 0 (s)", key="h"
            )
        steps = self.criterion.steps
        try:
            sim = _quiet_class(self.cls)(
                self.model, float(h), chunk=min(steps, 500), **self.options
            )
            self.settings = sim.settings()
            with np.errstate(over="ignore", invalid="ignore"):
                plus = sim.run(self.x_eq + self.d0, steps * float(h), u=self.u0).states
                minus = sim.run(self.x_eq - self.d0, steps * float(h), u=self.u0).states
                ratios = self.amplitudes(self.x_eq + 0.5 * (plus - minus), float(h))
            growth = float(np.max(ratios, initial=1.0)) if np.all(np.isfinite(ratios)) else math.inf
            stable = growth <= self.criterion.growth
            return Probe(
                float(h),
                stable,
                growth,
                "" if stable else f"a modal amplitude grew {growth:.4g}-fold",
                "" if stable else "growth",
            )
        except (SimulationError, SolverError) as exc:
            kind = "solver" if isinstance(exc, SolverError) else "diverged"
            return Probe(float(h), False, math.inf, str(exc).splitlines()[0][:300], kind)


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
    if not (isinstance(expansion, (int, float)) and 1.0 < expansion <= 1e3):
        raise SpecError(
            f"expansion = {expansion!r} is not allowed; allowed: a number in (1, 1000]",
            key="expansion",
        )
    if not (0 < rel_tol < 1):
        raise SpecError(
            f"rel_tol = {rel_tol!r} is not allowed; allowed: a number in (0, 1)", key="rel_tol"
        )
    if not (0 < omega_h_floor <= omega_h_start <= omega_h_cap and math.isfinite(omega_h_cap)):
        raise SpecError(
            f"omega_h_floor = {omega_h_floor!r}, omega_h_start = {omega_h_start!r}, omega_h_cap "
            f"= {omega_h_cap!r} "
            "are not allowed; allowed: 0 < floor <= start <= cap < inf",
            key="omega_h_start",
        )
    probe = StabilityProbe(
        model, integrator, x0, u0, criterion=criterion, integrator_options=integrator_options
    )
    omega_max = probe.omega_max
    probes: list[Probe] = []

    def run(y: float) -> bool:
        p = probe(y / omega_max)
        probes.append(p)
        return p.stable

    def result(y_measured: float, y_unstable: float, outcome: Outcome) -> StabilityResult:
        return StabilityResult(
            integrator=probe.name,
            h_measured=y_measured / omega_max,
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

    y = omega_h_start
    if run(y):
        while y < omega_h_cap:
            y_next = min(expansion * y, omega_h_cap)
            if not run(y_next):
                y_stable, y_unstable = y, y_next
                break
            y = y_next
        else:
            return result(omega_h_cap, math.inf, "stable_at_cap")
    else:
        while y > omega_h_floor:
            y_next = max(y / expansion, omega_h_floor)
            if run(y_next):
                y_stable, y_unstable = y_next, y
                break
            y = y_next
        else:
            return result(0.0, omega_h_floor, "unstable_at_floor")
    while y_unstable / y_stable - 1.0 > rel_tol:
        mid = math.sqrt(y_stable * y_unstable)
        if run(mid):
            y_stable = mid
        else:
            y_unstable = mid
    return result(y_stable, y_unstable, "bracketed")


__all__ = [
    "Probe",
    "StabilityCriterion",
    "StabilityProbe",
    "StabilityResult",
    "largest_stable_step",
    "linearization_function",
    "linearize",
    "refine_equilibrium",
]
