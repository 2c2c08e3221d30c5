"""Baumgarte stabilisation under Newmark: discrete error dynamics and the beam-over-supports
sweep.

Constraint-error dynamics (see ``docs/explanation/baumgarte.md`` for the derivation)
    :mod:`flexctrl.dynamics.fem.newmark_dae` imposes Eq 49, ``Phi_q qdd = h - 2 gamma Phidot
    - beta^2 Phi``, so along the computed motion the violation ``e = Phi`` obeys
    ``e'' = -2 gamma e' - beta^2 e`` at every step, with the feedback evaluated at
    the previous step (``feedback="explicit"``, Eq 54, the paper's choice) or at the
    new one (``"implicit"``).  ``q`` is advanced by the Newmark rule; for a
    constraint ``Phi = A(t) q`` the triple ``x = (e, h e', h^2 e'')`` then follows the
    same rule up to a small local *defect* ``d_k`` (the Newmark rule does not commute
    with the time-varying ``A(t)``; O(h^3) per step)::

        x_{k+1} = N x_k + c h^2 e''_{k+1} + d_k ,   h^2 e''_{k+1} = l . x_{k or k+1} ,
        l = (-(beta h)^2, -2 gamma h, 0)   ->   x_{k+1} = G x_k + M d_k .

    With ``g = gamma h``, ``b = beta h`` and (alpha, delta) = (1/4, 1/2) the
    characteristic polynomial of ``G`` is::

        explicit:  z (z - 1)^2 + g (z^2 - 1) + (b^2 / 4) (z + 1)^2
        implicit:  (z - 1)^2 + g (z^2 - 1) + (b^2 / 4) (z + 1)^2      (times z)

    The implicit one is the trapezoidal rule applied to ``e'' + 2 gamma e' + beta^2 e
    = 0`` (A-stable: stable for every ``h``, deadbeat at ``g = b = 2``, and
    ``|z| -> 1`` with alternating sign as ``g -> inf``).  The explicit one has the
    extra ``z``: the feedback acts one step late; by Jury's test it is stable only
    for ``gamma = beta`` and ``gamma h < 3 - sqrt(5) = 0.764`` (:data:`EXPLICIT_LIMIT`),
    and it decays fastest at ``gamma h = 0.455`` (``|z| = 0.739``).  A steady defect
    ``d`` in ``e`` per step gives the fixed point ``e = 2 gamma d / (beta^2 h)``
    (either feedback) and ``e' = -d / h`` for every gamma: Baumgarte
    pushes ``|Phi|`` down as ``1/gamma`` but cannot reduce ``|Phidot|`` below the
    defect rate.

Measured side
    :func:`run_point` runs the beam case at one (dt, gamma, beta, feedback); a run
    whose violation exceeds ``max_violation`` is *recorded* as unstable with the
    time it did so (:class:`SweepPoint`), never returned as NaN.
    :func:`constraint_states` and :func:`step_defects` extract ``x_k`` and
    ``d_k`` from a run, and :func:`propagate_errors` predicts the violation of any
    other gamma from the defects of a gamma = 0 run (the linear error model,
    ``x_{k+1} = G x_k + M d_k``, :func:`defect_gain`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from flexctrl.dynamics.fem.newmark_dae import DAEProblem, DAEResult, simulate
from flexctrl.dynamics.fem.sliding_beam import SlidingBeamCase, SlidingBeamModel
from flexctrl.errors import SimulationError, SolverError

Array = NDArray[np.float64]
Feedback = Literal["explicit", "implicit"]
FEEDBACKS: tuple[str, ...] = ("explicit", "implicit")

#: ``gamma h`` at which explicit feedback with ``gamma = beta`` becomes unstable
#: under trapezoidal Newmark (root of Jury's condition ``1 - a0^2 = a1 - a0 a2``).
EXPLICIT_LIMIT: float = 3.0 - math.sqrt(5.0)


def _check_feedback(feedback: str) -> None:
    if feedback not in FEEDBACKS:
        raise ValueError(
            f"feedback {feedback!r} is not allowed; allowed: {', '.join(map(repr, FEEDBACKS))}"
        )


# -- discrete error dynamics ------------------------------------------------------------


def newmark_error_matrices(alpha: float = 0.25, delta: float = 0.5) -> tuple[Array, Array]:
    """``(N, c)`` with ``x_{i+1} = N x_i + c s_{i+1} + d_i`` for ``x = (e, h e', h^2 e'')`` and ``s
    = h^2 e''``.

    The Newmark rule: ``e_{i+1} = e_i + h e'_i + h^2 ((1/2 - alpha) e''_i + alpha e''_{i+1})``,
    ``e'_{i+1} = e'_i + h ((1 - delta) e''_i + delta e''_{i+1})``; ``d_i`` is the defect.
    """
    newmark = np.array([[1.0, 1.0, 0.5 - alpha], [0.0, 1.0, 1.0 - delta], [0.0, 0.0, 0.0]])
    return newmark, np.array([alpha, delta, 1.0])


def _law(gamma_dt: float, beta_dt: float) -> Array:
    """Row ``l`` with ``h^2 e'' = l . x`` (Eq 49: ``e'' = -2 gamma e' - beta^2 e``)."""
    return np.array([-(float(beta_dt) ** 2), -2.0 * float(gamma_dt), 0.0])


def defect_gain(
    gamma_dt: float,
    beta_dt: float,
    feedback: Feedback = "explicit",
    alpha: float = 0.25,
    delta: float = 0.5,
) -> Array:
    """``M`` in ``x_{i+1} = G x_i + M d_i``: identity for explicit feedback, ``(I - c l)^-1`` for
    implicit.

    With implicit feedback the new step's acceleration reacts to the defect of the same
    step, so the defect enters filtered.
    """
    _check_feedback(feedback)
    if feedback == "explicit":
        return np.eye(3)
    _, into = newmark_error_matrices(alpha, delta)
    return np.asarray(np.linalg.inv(np.eye(3) - np.outer(into, _law(gamma_dt, beta_dt))), float)


def error_amplification(
    gamma_dt: float,
    beta_dt: float,
    feedback: Feedback = "explicit",
    alpha: float = 0.25,
    delta: float = 0.5,
) -> Array:
    """Amplification matrix ``G`` of the constraint error ``x = (e, h e', h^2 e'')`` over one step.

    Parameters
    ----------
    gamma_dt, beta_dt
        ``gamma h`` and ``beta h`` (dimensionless; gamma, beta in 1/s, h in s).
    feedback
        ``"explicit"``: Baumgarte terms from step i (Eq 54), ``G = N + c l``;
        ``"implicit"``: from step i+1, ``G = (I - c l)^-1 N``.
    alpha, delta
        Newmark parameters (see :func:`newmark_error_matrices`).

    Returns
    -------
    numpy.ndarray
        (3, 3); ``x_{i+1} = G x_i`` without defects.
    """
    _check_feedback(feedback)
    newmark, into = newmark_error_matrices(alpha, delta)
    law = _law(gamma_dt, beta_dt)
    if feedback == "explicit":
        return newmark + np.outer(into, law)
    return defect_gain(gamma_dt, beta_dt, feedback, alpha, delta) @ newmark


def spectral_radius(
    gamma_dt: float,
    beta_dt: float,
    feedback: Feedback = "explicit",
    alpha: float = 0.25,
    delta: float = 0.5,
) -> float:
    """Largest ``|z|`` of :func:`error_amplification`: the per-step factor of a free violation."""
    return float(
        np.max(
            np.abs(
                np.linalg.eigvals(error_amplification(gamma_dt, beta_dt, feedback, alpha, delta))
            )
        )
    )


def stability_limit(
    beta_over_gamma: float = 1.0,
    feedback: Feedback = "explicit",
    alpha: float = 0.25,
    delta: float = 0.5,
    gamma_dt_max: float = 1e4,
) -> float:
    """Smallest ``gamma h`` above which the error dynamics are unstable (``inf`` if none up to
    ``gamma_dt_max``).

    Scans ``gamma h`` on a logarithmic grid for the first unstable point and bisects
    (to 1e-12 relative) between it and the last stable one.  For ``gamma = beta``,
    explicit feedback and trapezoidal Newmark the result is :data:`EXPLICIT_LIMIT`.
    """

    def unstable(g: float) -> bool:
        return spectral_radius(g, beta_over_gamma * g, feedback, alpha, delta) > 1.0 + 1e-12

    grid = np.geomspace(1e-4, gamma_dt_max, 400)
    flags = [unstable(g) for g in grid]
    if not any(flags):
        return math.inf
    k = flags.index(True)
    if k == 0:
        return 0.0
    lo, hi = float(grid[k - 1]), float(grid[k])
    while hi - lo > 1e-12 * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if unstable(mid) else (mid, hi)
    return 0.5 * (lo + hi)


def fastest_decay(
    beta_over_gamma: float = 1.0,
    feedback: Feedback = "explicit",
    alpha: float = 0.25,
    delta: float = 0.5,
) -> tuple[float, float]:
    """``(gamma h, |z|)`` where a free violation decays fastest per step: beyond it more gamma stops
    helping.

    Golden-section search of :func:`spectral_radius` over ``(0, limit)`` (limit: the
    stability limit, or 100 for unconditionally stable rules) after a coarse scan.
    """
    top = min(stability_limit(beta_over_gamma, feedback, alpha, delta), 100.0)
    rho = lambda g: spectral_radius(g, beta_over_gamma * g, feedback, alpha, delta)  # noqa: E731
    grid = np.geomspace(1e-3, top, 300)[:-1]
    k = int(np.argmin([rho(g) for g in grid]))
    lo, hi = float(grid[max(k - 1, 0)]), float(grid[min(k + 1, grid.size - 1)])
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    while hi - lo > 1e-10 * hi:
        a, b = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
        lo, hi = (lo, b) if rho(a) <= rho(b) else (a, hi)
    g = 0.5 * (lo + hi)
    return g, rho(g)


def steady_drift_response(
    gamma_dt: float, beta_dt: float, alpha: float = 0.25, delta: float = 0.5
) -> Array:
    """Fixed point ``(e, h e', h^2 e'')`` per unit position defect per step, for either feedback.

    Solves ``(I - N - c l) x = (1, 0, 0)`` (the fixed point is the same for explicit and
    implicit feedback); for ``gamma = beta`` and trapezoidal Newmark it is
    ``(2 / (gamma h), -1, 0)``.  Raises :class:`numpy.linalg.LinAlgError` for ``beta = 0``
    (no fixed point: the drift grows without bound).
    """
    newmark, into = newmark_error_matrices(alpha, delta)
    system = np.eye(3) - newmark - np.outer(into, _law(gamma_dt, beta_dt))
    return np.linalg.solve(system, np.array([1.0, 0.0, 0.0]))


def predicted_regime(
    gamma_dt: float,
    beta_over_gamma: float = 1.0,
    feedback: Feedback = "explicit",
    alpha: float = 0.25,
    delta: float = 0.5,
) -> str:
    """``"none"`` (gamma = 0), ``"helps"`` (below :func:`fastest_decay`), ``"saturated"`` or
    ``"unstable"``."""
    if gamma_dt <= 0.0:
        return "none"
    if gamma_dt > stability_limit(beta_over_gamma, feedback, alpha, delta):
        return "unstable"
    return (
        "helps"
        if gamma_dt <= fastest_decay(beta_over_gamma, feedback, alpha, delta)[0]
        else "saturated"
    )


# -- measured side ----------------------------------------------------------------------


def constraint_states(model: SlidingBeamModel, result: DAEResult) -> Array:
    """Signed ``(e, h e', h^2 e'')`` of every constraint at every step, shape (steps + 1, 3, m).

    ``e = Phi``, ``e' = Phi_q qd + Phi_t`` and ``e'' = Phi_q qdd - h(q, qd)`` (the exact
    second derivative of ``Phi`` along the discrete state); units m, m, m.
    """
    problem = model.problem()
    h = result.dt
    rows = []
    for k, t in enumerate(result.t):
        q, qd, qdd = result.q[k], result.qd[k], result.qdd[k]
        e = problem.phi(q, t)
        ed = problem.phi_q(q, t) @ qd + problem.phi_t(q, t)
        edd = problem.phi_q(q, t) @ qdd - problem.h(q, qd, t)
        rows.append(np.stack([e, h * ed, h * h * edd]))
    return np.asarray(rows)


def step_defects(states: Array, alpha: float = 0.25, delta: float = 0.5) -> Array:
    """``d_k = x_{k+1} - N x_k - c s_{k+1}`` (shape (steps, 3, m), m): what the Newmark rule does
    not explain.

    Independent of gamma, beta and the feedback variant (they only set ``s_{k+1}``,
    which is taken from the states).
    """
    newmark, into = newmark_error_matrices(alpha, delta)
    return (
        states[1:]
        - np.einsum("ij,kjl->kil", newmark, states[:-1])
        - into[None, :, None] * states[1:, 2:3, :]
    )


@dataclass(frozen=True)
class ErrorPrediction:
    """Violation predicted by the linear error model (m, m/s; ``steps_bounded`` steps stayed within
    the bound)."""

    max_phi: float
    final_phi: float
    max_phidot: float
    final_phidot: float
    steps_bounded: int
    exceeded: bool


def propagate_errors(
    x0: Array,
    defects: Array,
    gamma_dt: float,
    beta_dt: float,
    dt: float,
    feedback: Feedback = "explicit",
    alpha: float = 0.25,
    delta: float = 0.5,
    bound: float = math.inf,
) -> ErrorPrediction:
    """Run ``x_{k+1} = G x_k + M d_k`` from ``x0`` (shape (3, m)) until the defects end or ``|e|``
    exceeds ``bound`` (m)."""
    G = error_amplification(gamma_dt, beta_dt, feedback, alpha, delta)
    gain = defect_gain(gamma_dt, beta_dt, feedback, alpha, delta)
    x = np.array(x0, dtype=float)
    max_e, max_ed = float(np.max(np.abs(x[0]))), float(np.max(np.abs(x[1]))) / dt
    steps, exceeded = 0, False
    for d in defects:
        x_new = G @ x + gain @ d
        e = float(np.max(np.abs(x_new[0])))
        if not e <= bound:
            exceeded = True
            break
        x = x_new
        steps += 1
        max_e, max_ed = max(max_e, e), max(max_ed, float(np.max(np.abs(x[1]))) / dt)
    return ErrorPrediction(
        max_phi=max_e,
        final_phi=float(np.max(np.abs(x[0]))),
        max_phidot=max_ed,
        final_phidot=float(np.max(np.abs(x[1]))) / dt,
        steps_bounded=steps,
        exceeded=exceeded,
    )


@dataclass(frozen=True)
class SweepPoint:
    """One measured (dt, gamma, beta, feedback) run of the beam case.

    Attributes
    ----------
    dt, gamma, beta, feedback
        Step (s, as used), Baumgarte parameters (1/s), feedback variant.
    bounded : bool
        The violation stayed within ``max_violation`` for the whole duration.
    blowup_time : float or None
        Time (s) of the step whose ``max|Phi|`` exceeded ``max_violation`` (None if bounded).
    result : DAEResult
        Histories up to the last bounded step (the whole run if bounded).
    tip : numpy.ndarray
        Transverse displacement of the tracked end over ``result.t`` (m).
    error : str
        The integrator's message for an unstable run ("" otherwise).
    """

    dt: float
    gamma: float
    beta: float
    feedback: str
    bounded: bool
    blowup_time: float | None
    result: DAEResult | None
    tip: Array
    error: str = ""

    @property
    def time_bounded(self) -> float:
        """Last time (s) at which the violation was within the bound."""
        return float(self.result.t[-1]) if self.result is not None else 0.0

    def growth_per_step(self, window: int = 200) -> float | None:
        """Fitted per-step factor of ``max|Phi|`` over the last half (at most ``window`` steps)
        before blow-up.

        None for bounded runs or fewer than 4 usable steps.  Least squares on ``log max|Phi|``,
        so an oscillating (complex-root) envelope is averaged.
        """
        if self.bounded or self.result is None:
            return None
        v = self.result.phi_violation[1:]
        n = min(window, v.size // 2)
        tail = v[v.size - n :]
        if n < 4 or np.any(tail <= 0.0):
            return None
        slope = np.polyfit(np.arange(n, dtype=float), np.log(tail), 1)[0]
        return float(math.exp(slope))


def _last_time_probe(problem):
    """The problem with ``phi`` wrapped to remember the latest time it was evaluated at."""
    seen = {"t": -math.inf}
    phi = problem.phi

    def recorded(q, t):
        seen["t"] = max(seen["t"], float(t))
        return phi(q, t)

    return dataclasses.replace(problem, phi=recorded), seen


def run_point(
    case: SlidingBeamCase,
    n_elements: int,
    dt: float,
    gamma: float,
    beta: float,
    *,
    feedback: Feedback = "explicit",
    duration: float | None = None,
    alpha: float = 0.25,
    delta: float = 0.5,
    axial_shortening: bool = True,
    max_violation: float = 1e-3,
) -> SweepPoint:
    """Simulate the sliding beam at one setting; an unbounded violation is recorded, not raised.

    Parameters
    ----------
    case, n_elements, axial_shortening
        As :class:`~flexctrl.dynamics.fem.sliding_beam.SlidingBeamModel`.
    dt, duration
        Newmark step and simulated time, s (duration default ``max(T, 1 s)``).
    gamma, beta
        Baumgarte parameters, 1/s (>= 0; 0 switches the term off).
    feedback, alpha, delta
        See :func:`flexctrl.dynamics.fem.newmark_dae.simulate`.
    max_violation
        ``max|Phi|`` (m) beyond which the run counts as unstable; it is then re-run up
        to the last bounded step so its histories are kept.

    Returns
    -------
    SweepPoint
    """
    _check_feedback(feedback)
    if gamma < 0 or beta < 0:
        raise ValueError(f"gamma = {gamma}, beta = {beta}: allowed: >= 0 (1/s)")
    model = SlidingBeamModel(case, n_elements, axial_shortening)
    t_end = max(case.T, 1.0) if duration is None else float(duration)
    q0 = model.initial_shape()
    qd0 = np.zeros_like(q0)

    def run(problem: DAEProblem, until: float, step: float) -> DAEResult:
        return simulate(
            problem,
            q0,
            qd0,
            until,
            step,
            gamma=gamma,
            beta=beta,
            alpha=alpha,
            delta=delta,
            feedback=feedback,
            max_violation=max_violation,
        )

    problem, seen = _last_time_probe(model.problem())
    try:
        res = run(problem, t_end, dt)
        return SweepPoint(res.dt, gamma, beta, feedback, True, None, res, res.q[:, model.tip_dof])
    except (SimulationError, SolverError) as exc:
        message = str(exc)
        blowup = seen["t"]
    n_steps = max(1, int(np.ceil(t_end / dt - 1e-9)))
    h = t_end / n_steps
    k = int(round(blowup / h))
    if k <= 1:
        return SweepPoint(
            h, gamma, beta, feedback, False, blowup, None, np.array([q0[model.tip_dof]]), message
        )
    # same step sequence, stopped before the failing step (the first k - 1 steps are identical)
    res = run(model.problem(), (k - 1) * h, h)
    return SweepPoint(
        res.dt, gamma, beta, feedback, False, blowup, res, res.q[:, model.tip_dof], message
    )
