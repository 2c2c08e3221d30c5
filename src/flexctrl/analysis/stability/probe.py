"""Probe runs of an integrator about an equilibrium: is a step stable?

The probe (:class:`StabilityProbe`), which
:func:`~flexctrl.analysis.stability.step_search.largest_stable_step` bisects with
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

The theory it is compared with (``h_theory``, :attr:`StabilityResult.theory`) is
:mod:`flexctrl.analysis.stability.theory`.

Units: SI throughout (s, rad/s; amplitudes in m or rad).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from flexctrl.analysis.stability.equilibrium import (
    check_spectrum,
    checked_state,
    linearization_function,
    linearize,
    modal_basis,
    refine_equilibrium,
)
from flexctrl.analysis.stability.theory import (
    EIGENVALUE_TOL,
    THEORY_METHODS,
    TheoryLimit,
    theoretical_step_limit,
)
from flexctrl.errors import SimulationError, SolverError, SpecError
from flexctrl.sim import get_integrator

# -- linearisation --------------------------------------------------------------------


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
                f"amplitude = {self.amplitude!r} is not allowed; allowed: a number in (0, "
                "0.1] (m or rad)",
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


@functools.lru_cache(maxsize=8)
def _quiet_class(cls: type) -> type:
    """``cls`` with a one-line divergence message (its advice computes a Jacobian: seconds for big
    models)."""

    def stability_advice(self, states=()) -> str:
        return "(stability probe)"

    return type(
        f"{cls.__name__}Probe",
        (cls,),
        {"stability_advice": stability_advice, "__module__": __name__},
    )


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
    >>> model = fc.load_model("subedi3link", fidelity="amm:1", gravity=[0.0, 0.0])
    >>> op = fc.equilibrium(model, [0.3, -0.2, 0.1])
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

        self.model = model
        self.criterion = criterion or StabilityCriterion()
        self.cls = get_integrator(integrator)
        self.options = dict(integrator_options or {})
        for key in ("chunk", "u_function"):
            if key in self.options:
                raise SpecError(
                    f"integrator option '{key}' is set by the probe; allowed: other options "
                    f"of {self.cls.name}",
                    key=key,
                )
        x, u = checked_state(model, x0, u0)
        self.u0 = u
        function = linearization_function(model)
        self.x_eq, self.residual = refine_equilibrium(
            model, x, u, tolerance=1e-2 * self.criterion.amplitude, function=function
        )
        _f, A = linearize(model, self.x_eq, u, function)
        self.eigenvalues = np.linalg.eigvals(A)
        self.omega_max = float(np.max(np.abs(self.eigenvalues), initial=0.0))
        check_spectrum(model, self.eigenvalues, self.omega_max)
        lam, vectors, rows = modal_basis(A, model.n_q, EIGENVALUE_TOL)
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
                f"{self.criterion.amplitude:g}: its remaining offset is {self.offset:.3g} of a "
                f"mode's initial amplitude (max |f| = {self.residual:.3g}); allowed: at most "
                "1e-3 (a larger amplitude, or a better equilibrium)",
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
            # a class is hashable; mypy takes the instances' __eq__ for the class's own
            sim = _quiet_class(cast(Hashable, self.cls))(
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


__all__ = ["Probe", "StabilityCriterion", "StabilityProbe"]
