"""Newmark's method for any model, behind the common :class:`~flexctrl.sim.integrator.Integrator`.

This adapter runs :func:`flexctrl.dynamics.fem.newmark.simulate_model_newmark`'s
machinery (the model as a :class:`~flexctrl.dynamics.fem.newmark_dae.DAEProblem`, built
once by :func:`~flexctrl.dynamics.fem.newmark.model_dae_problem`, integrated by
:func:`flexctrl.dynamics.fem.newmark_dae.simulate` chunk by chunk) so that it takes a
state ``x = (q, qd)``, held torques and an optional ``u_function`` like every
other integrator and returns a :class:`~flexctrl.sim.trajectory.Trajectory`
with the same divergence checks.  The joints are free (no constraints).

Each step solves ``M(q) qdd + c(q, qd) + g(q) + K q + D qd = B tau`` at the new
time by Newton's method (modified Newton with the ``tangent`` of
:func:`~flexctrl.dynamics.fem.newmark.model_dae_problem`; the residual is exact,
so the converged step does not depend on the tangent) with

``q_{i+1} = q_i + h qd_i + h^2 ((1/2 - alpha) qdd_i + alpha qdd_{i+1})``,
``qd_{i+1} = qd_i + h ((1 - delta) qdd_i + delta qdd_{i+1})``.

Stability
    For a linear mode with frequency ``omega`` and damping ratio ``zeta`` Newmark
    is unconditionally stable when ``2 alpha >= delta >= 1/2``; the default
    ``alpha = 1/4, delta = 1/2`` (average acceleration, equivalent to the
    trapezoidal rule with ``R(z) = (1 + z/2) / (1 - z/2)``) keeps ``|R| = 1`` on
    undamped modes for every step: no numerical damping, only a period error.
    For ``delta >= 1/2`` and ``2 alpha < delta`` the step is stable only for
    ``omega h <= Omega_crit`` with
    ``Omega_crit = (zeta d + sqrt(delta/2 - alpha + zeta^2 d^2)) / (delta/2 - alpha)``,
    ``d = delta - 1/2`` (Hughes, *The Finite Element Method*, 2000, Sec. 9.1), e.g. 2 for the
    central-difference choice ``alpha = 0, delta = 1/2`` undamped; ``delta < 1/2`` makes it
    unstable.  :attr:`Newmark.stability_limit` is the undamped value.

Torque inputs
    The residual at the end of step ``i`` uses that step's held torque sample (plus
    ``u_function`` at the end time); the acceleration at its start was solved
    with the previous step's sample.  The trapezoidal rule therefore sees a torque
    jump half a step late: an O(h) error at each jump of a piecewise-constant
    input, none for smooth or constant inputs.

Cost
    The steps run in Python with numpy linear algebra (a few CasADi evaluations
    and one dense solve per Newton iteration), so Newmark pays off only where its
    step can be much longer than an explicit method's (stiff finite-element models).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, Literal

import casadi as ca
import numpy as np

from flexctrl.dynamics.fem.newmark import model_dae_problem
from flexctrl.dynamics.fem.newmark_dae import simulate
from flexctrl.errors import SpecError
from flexctrl.sim.integrator import Integrator

Tangent = Literal["potential", "stiffness", "exact"]
TANGENTS = ("potential", "stiffness", "exact")


def newmark_critical_step(alpha: float, delta: float, zeta: float = 0.0) -> float:
    """Largest stable ``omega h`` of Newmark on a linear mode with damping ratio ``zeta``.

    Parameters
    ----------
    alpha, delta
        Newmark parameters (Hughes' beta and gamma).
    zeta
        Modal damping ratio (>= 0).

    Returns
    -------
    float
        ``inf`` when unconditionally stable (``2 alpha >= delta >= 1/2``), 0 when
        unstable at every step (``delta < 1/2``), else Hughes' ``Omega_crit``
        (see module docstring).

    Examples
    --------
    >>> newmark_critical_step(0.25, 0.5)
    inf
    >>> newmark_critical_step(0.0, 0.5)
    2.0
    """
    if delta < 0.5:
        return 0.0
    if 2.0 * alpha >= delta:
        return math.inf
    excess = delta - 0.5
    gap = 0.5 * delta - alpha
    return (zeta * excess + math.sqrt(gap + (zeta * excess) ** 2)) / gap


class Newmark(Integrator):
    """Newmark's method on the model's equations of motion (see module docstring).

    Parameters
    ----------
    model, dt, u_function, chunk, energy_factor
        See :class:`~flexctrl.sim.integrator.Integrator`.
    alpha, delta
        Newmark parameters: 0.25, 0.5 (average acceleration, trapezoidal rule) by
        default; ``alpha`` in [0, 0.5], ``delta`` in [0.5, 1].
    tangent
        Newton tangent: ``"potential"`` (default), ``"stiffness"`` or ``"exact"``
        (:func:`~flexctrl.dynamics.fem.newmark.model_dae_problem`).
    newton_tol
        Newton stops when ``max|dq| <= newton_tol (1 + max|q|)``.
    max_iterations
        Newton iterations per step before
        :class:`~flexctrl.dynamics.fem.newmark_dae.NewtonConvergenceError`.
    """

    name: ClassVar[str] = "newmark"
    stability_limit: float = math.inf

    def __init__(
        self,
        model,
        dt: float,
        *,
        u_function: ca.Function | None = None,
        chunk: int = 1000,
        energy_factor: float = 100.0,
        alpha: float = 0.25,
        delta: float = 0.5,
        tangent: Tangent = "potential",
        newton_tol: float = 1e-10,
        max_iterations: int = 30,
    ):
        super().__init__(model, dt, u_function=u_function, chunk=chunk, energy_factor=energy_factor)
        for key, value, low, high in (("alpha", alpha, 0.0, 0.5), ("delta", delta, 0.5, 1.0)):
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not low <= value <= high
            ):
                raise SpecError(
                    f"{key} = {value!r} is not allowed; allowed: a number in [{low:g}, {high:g}]",
                    key=key,
                )
        if tangent not in TANGENTS:
            raise SpecError(
                f"tangent = {tangent!r} is not allowed; allowed: {', '.join(map(repr, TANGENTS))}",
                key="tangent",
            )
        if (
            isinstance(newton_tol, bool)
            or not isinstance(newton_tol, (int, float))
            or not 0 < newton_tol < 1e-2
        ):
            raise SpecError(
                f"newton_tol = {newton_tol!r} is not allowed; allowed: a number in (0, 1e-2)",
                key="newton_tol",
            )
        if (
            isinstance(max_iterations, bool)
            or not isinstance(max_iterations, int)
            or max_iterations < 1
        ):
            raise SpecError(
                f"max_iterations = {max_iterations!r} is not allowed; allowed: an integer >= 1",
                key="max_iterations",
            )
        self.alpha, self.delta = float(alpha), float(delta)
        self.tangent = tangent
        self.newton_tol = float(newton_tol)
        self.max_iterations = max_iterations
        #: Largest stable ``omega * dt`` of an undamped mode for these parameters (instance value).
        self.stability_limit = newmark_critical_step(self.alpha, self.delta)
        self._held = np.zeros((1, model.n_u))
        self._t0 = 0.0

    def settings(self) -> dict[str, Any]:
        """Integrator settings plus the Newmark parameters and Newton options."""
        out = super().settings()
        out.update(
            {
                "alpha": self.alpha,
                "delta": self.delta,
                "tangent": self.tangent,
                "newton_tol": self.newton_tol,
                "max_iterations": self.max_iterations,
            }
        )
        return out

    def _torque(self, t: float) -> np.ndarray:
        """Held sample of the step that ends at (or contains) ``t``, plus ``u_function(t)``."""
        k = self._held.shape[0]
        index = min(max(int(math.ceil((t - self._t0) / self.dt - 1e-9)) - 1, 0), k - 1)
        tau = self._held[index]
        if self.u_function is not None:
            tau = tau + np.asarray(self.u_function(t), dtype=float).ravel()
        return tau

    def _setup(self) -> None:
        self._problem = model_dae_problem(self.model, self._torque, tangent=self.tangent)

    def _advance(self, x0: np.ndarray, times: np.ndarray, U: np.ndarray) -> tuple[np.ndarray, None]:
        k = U.shape[0]
        n = self.model.n_q
        self._held, self._t0 = U, float(times[0])
        result = simulate(
            self._problem,
            x0[:n],
            x0[n:],
            float(times[k]),
            self.dt,
            t0=float(times[0]),
            alpha=self.alpha,
            delta=self.delta,
            newton_tol=self.newton_tol,
            max_iterations=self.max_iterations,
            max_violation=np.inf,
        )
        self.counters["newton_iterations"] = self.counters.get("newton_iterations", 0) + int(
            result.newton_iterations.sum()
        )
        return np.hstack([result.q[1:], result.qd[1:]]), None

    def stability_advice(self, states=()) -> str:
        """Newmark-specific advice (see module docstring)."""
        if math.isinf(self.stability_limit):
            return (
                f"Newmark with alpha = {self.alpha:g}, delta = {self.delta:g} is unconditionally "
                "stable on linear modes, so this is not a step-size instability of the method: "
                "check the model, the initial state and the torques, or reduce dt so Newton "
                "converges on the nonlinear terms."
            )
        return super().stability_advice(states)
