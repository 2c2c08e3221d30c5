"""Newmark integration of constrained equations of motion (Pan, Scott & Ulsoy 1990, Sec. 4).

Solves ``M(q,t) qdd + Phi_q(q,t)^T lam = f(q, qd, t)`` with holonomic constraints
``Phi(q, t) = 0`` (Eqs 44-45).

Index reduction and Baumgarte stabilisation
    The constraints are imposed at acceleration level, ``Phi_q qdd = h`` (Eq 47) with
    ``h = -(d(Phi_q qd + Phi_t)/dq) qd - d(Phi_q qd + Phi_t)/dt`` (= the paper's
    ``-Psi_q qd - 2 Phi_qt qd - Phi_tt``), plus Baumgarte feedback (Eq 49)::

        Phi_q qdd = h - 2 gamma Phidot - beta^2 Phi .

    This makes the violation obey ``Phidd + 2 gamma Phidot + beta^2 Phi = 0``
    (stable for gamma, beta > 0).  The printed Eq 54 has ``+ beta^2 Phi``; that
    gives ``s^2 + 2 gamma s - beta^2 = 0``, whose root ``s = -gamma +
    sqrt(gamma^2 + beta^2) > 0`` makes any violation grow (rate 2.07/s for
    gamma = beta = 5).  We therefore use the Eq 49 sign and treat Eq 54's sign as a
    misprint; ``baumgarte_form="eq54_printed"`` reproduces it for demonstration
    only (tests show it diverges).  As in Eq 54, the feedback uses the violation of
    the *previous* step (``feedback="explicit"``, the paper's choice), which limits
    gamma*dt and beta*dt; ``feedback="implicit"`` evaluates it at the new step.

Newmark (Eqs 50-54)
    ``qdd_{i+1} = c0 (q_{i+1} - q_i) - qd_i / (alpha dt) - (1/(2 alpha) - 1) qdd_i``,
    ``qd_{i+1} = qd_i + dt ((1 - delta) qdd_i + delta qdd_{i+1})``, ``c0 = 1/(alpha dt^2)``.
    Substituting into the dynamics and the stabilised constraint gives n + m
    equations in ``(q_{i+1}, lam_{i+1})`` solved by Newton's method.  The Newton
    matrix is ``[[c0 M + c1 C_t + K_t, Phi_q^T], [c0 Phi_q - h_q - c1 h_qd, 0]]``
    (``K_t = -df/dq``, ``C_t = -df/dqd``, ``c1 = delta / (alpha dt)``); the
    q-dependence of ``M`` and ``Phi_q`` is left out of it (modified Newton, the
    converged step is still exact) unless ``jacobian="fd"``.  For
    ``DAEProblem.linear`` one solve per step is exact and no re-check is made.

Initial accelerations and multipliers (Eqs 55-56) come from the augmented system
``[[M, Phi_q^T], [Phi_q, 0]] (qdd, lam) = (f, h - 2 gamma Phidot - beta^2 Phi)``,
equivalent to Eqs 55-56 when ``M`` is invertible and usable when it is not.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from flexctrl.errors import SimulationError, SolverError

Array = NDArray[np.float64]


class ConstraintViolationError(SimulationError):
    """The constraint violation exceeded its bound or became non-finite."""


class NewtonConvergenceError(SolverError):
    """The Newton iteration of a Newmark step did not converge."""


@dataclass(frozen=True)
class DAEProblem:
    """``M(q,t) qdd + Phi_q^T lam = f(q,qd,t)``, ``Phi(q,t) = 0`` as callables of numpy arrays.

    ``mass(q,t)`` (n,n); ``force(q,qd,t)`` (n,); ``phi(q,t)``, ``phi_t(q,t)`` (m,);
    ``phi_q(q,t)`` (m,n); ``h(q,qd,t)`` (m,), the right side of ``Phi_q qdd = h``
    (Eq 47).  Optional tangents ``force_q``, ``force_qd`` (n,n) and ``h_q``,
    ``h_qd`` (m,n) give the Newton matrix directly; without all four it is formed
    by finite differences.  ``linear=True`` promises that M and Phi_q do not depend
    on q and that f and h are affine in (q, qd) with exact tangents.
    See :func:`flexctrl.dynamics.fem.casadi_dae.casadi_problem` for building one from CasADi
    expressions.
    """

    n_q: int
    n_c: int
    mass: Callable[[Array, float], Array]
    force: Callable[[Array, Array, float], Array]
    phi: Callable[[Array, float], Array]
    phi_q: Callable[[Array, float], Array]
    phi_t: Callable[[Array, float], Array]
    h: Callable[[Array, Array, float], Array]
    force_q: Callable[[Array, Array, float], Array] | None = None
    force_qd: Callable[[Array, Array, float], Array] | None = None
    h_q: Callable[[Array, Array, float], Array] | None = None
    h_qd: Callable[[Array, Array, float], Array] | None = None
    linear: bool = False

    @property
    def has_tangents(self) -> bool:
        """Whether all four Newton tangents are given."""
        return all(g is not None for g in (self.force_q, self.force_qd, self.h_q, self.h_qd))


@dataclass(frozen=True)
class DAEResult:
    """Time histories of a Newmark run; row k belongs to ``t[k]``.

    ``phi_violation`` and ``phidot_violation`` are max-norms of ``Phi`` and
    ``Phi_q qd + Phi_t`` (units of the constraints and per second); ``wall_time``
    in s; ``newton_iterations`` per step (0 for the initial state).
    """

    t: Array
    q: Array
    qd: Array
    qdd: Array
    lam: Array
    phi_violation: Array
    phidot_violation: Array
    newton_iterations: NDArray[np.int_]
    wall_time: float
    dt: float
    gamma: float
    beta: float
    alpha: float
    delta: float


def _fd_jac(fun: Callable[[Array], Array], x: Array, f0: Array) -> Array:
    jac = np.empty((f0.size, x.size))
    for k in range(x.size):
        step = 1e-7 * max(1.0, abs(x[k]))
        xp = x.copy()
        xp[k] += step
        jac[:, k] = (fun(xp) - f0) / step
    return jac


class _Newmark:
    """The Newmark scheme with Baumgarte feedback on one :class:`DAEProblem` (module docstring)."""

    def __init__(
        self,
        problem: DAEProblem,
        *,
        dt: float,
        alpha: float,
        delta: float,
        gamma: float,
        beta: float,
        baumgarte_form: str,
        feedback: str,
        use_fd: bool,
    ):
        self.problem, self.n, self.m = problem, problem.n_q, problem.n_c
        self.dt, self.alpha, self.delta, self.gamma, self.beta = dt, alpha, delta, gamma, beta
        self.kb = -(beta**2) if baumgarte_form == "eq54_printed" else beta**2
        self.c0, self.c1 = 1.0 / (alpha * dt * dt), delta / (alpha * dt)
        self.feedback, self.use_fd = feedback, use_fd

    def violations(self, q: Array, qd: Array, t: float) -> tuple[Array, Array]:
        """``(Phi, Phidot)`` at ``(q, qd, t)``."""
        p = self.problem
        return (
            np.asarray(p.phi(q, t), float),
            np.asarray(p.phi_q(q, t), float) @ qd + np.asarray(p.phi_t(q, t), float),
        )

    def initial(self, q: Array, qd: Array, t0: float) -> tuple[Array, Array, Array, Array]:
        """``(qdd, lam, Phi, Phidot)``: consistent initial accelerations and multipliers.

        From the augmented system of Eqs 55-56 (module docstring).
        """
        p, n, m = self.problem, self.n, self.m
        phi, phid = self.violations(q, qd, t0)
        A = np.zeros((n + m, n + m))
        A[:n, :n] = p.mass(q, t0)
        Pq = np.asarray(p.phi_q(q, t0), float).reshape(m, n)
        A[:n, n:], A[n:, :n] = Pq.T, Pq
        rhs = np.concatenate(
            [
                np.asarray(p.force(q, qd, t0), float),
                np.asarray(p.h(q, qd, t0), float) - 2 * self.gamma * phid - self.kb * phi,
            ]
        )
        try:
            sol = np.linalg.solve(A, rhs)
        except np.linalg.LinAlgError as exc:
            raise NewtonConvergenceError(
                f"singular augmented matrix for the initial accelerations at "
                f"t = {t0:g} s (dependent constraints?)"
            ) from exc
        return sol[:n], sol[n:], phi, phid

    def run(
        self,
        q: Array,
        qd: Array,
        tgrid: Array,
        *,
        newton: tuple[float, int],
        bounds: tuple[float, float | None],
        labels: str,
    ) -> DAEResult:
        """Integrate from ``(q, qd)`` at ``tgrid[0]`` over ``tgrid``; see :func:`simulate`."""
        n, m, n_steps = self.n, self.m, tgrid.size - 1
        Q, QD, QDD = (np.empty((n_steps + 1, n)) for _ in range(3))
        LAM = np.empty((n_steps + 1, m))
        VP, VV = np.zeros(n_steps + 1), np.zeros(n_steps + 1)
        ITS = np.zeros(n_steps + 1, dtype=int)
        start = time.perf_counter()
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            qdd, lam, phi, phid = self.initial(q, qd, tgrid[0])
            Q[0], QD[0], QDD[0], LAM[0] = q, qd, qdd, lam
            VP[0] = np.max(np.abs(phi), initial=0.0)
            VV[0] = np.max(np.abs(phid), initial=0.0)
            for k in range(1, n_steps + 1):
                t = tgrid[k]
                step = self.step_from(t, q, qd, qdd, phi, phid)
                q, lam, its = step.solve(k, lam, *newton)
                qdd, qd = step.states(q)
                phi, phid = self.violations(q, qd, t)
                vp, vv = self._checked(k, t, q, phi, phid, bounds, labels)
                Q[k], QD[k], QDD[k], LAM[k], VP[k], VV[k], ITS[k] = q, qd, qdd, lam, vp, vv, its
        return DAEResult(
            t=tgrid,
            q=Q,
            qd=QD,
            qdd=QDD,
            lam=LAM,
            phi_violation=VP,
            phidot_violation=VV,
            newton_iterations=ITS,
            wall_time=time.perf_counter() - start,
            dt=self.dt,
            gamma=float(self.gamma),
            beta=float(self.beta),
            alpha=float(self.alpha),
            delta=float(self.delta),
        )

    def _checked(
        self,
        k: int,
        t: float,
        q: Array,
        phi: Array,
        phid: Array,
        bounds: tuple[float, float | None],
        labels: str,
    ) -> tuple[float, float]:
        """``(max|Phi|, max|Phidot|)`` after step ``k``, refused beyond ``bounds`` or non-finite."""
        max_violation, max_velocity_violation = bounds
        vp = np.max(np.abs(phi), initial=0.0)
        vv = np.max(np.abs(phid), initial=0.0)
        bad_v = max_velocity_violation is not None and not vv <= max_velocity_violation
        if not (vp <= max_violation and np.isfinite(vv)) or bad_v or not np.all(np.isfinite(q)):
            raise ConstraintViolationError(
                f"constraint violation grew without bound at step {k} (t = {t:.6g} s, "
                f"dt = {self.dt:.3g} s, {labels}): max|Phi| = {vp:.3g} "
                f"(bound {max_violation:g}), max|Phidot| = {vv:.3g} "
                f"(bound {max_velocity_violation})"
            )
        return vp, vv

    def step_from(
        self, t: float, q: Array, qd: Array, qdd: Array, phi: Array, phid: Array
    ) -> _Step:
        """The step that ends at ``t`` from the state ``(q, qd, qdd)`` and its violations."""
        dt, alpha, delta = self.dt, self.alpha, self.delta
        return _Step(
            self,
            t,
            q,
            qd,
            qdd,
            acc0=-qd / (alpha * dt) - (0.5 / alpha - 1.0) * qdd,
            vel0=qd + dt * (1.0 - delta) * qdd,
            fb_old=2 * self.gamma * phid + self.kb * phi,  # step-i violations (Eq 54)
        )


@dataclass(frozen=True)
class _Step:
    """One Newmark step: the state at its start and the Newton iteration for its end."""

    scheme: _Newmark
    t: float
    qi: Array
    qdi: Array
    qddi: Array
    acc0: Array
    vel0: Array
    fb_old: Array

    def states(self, qn: Array) -> tuple[Array, Array]:
        """``(qdd, qd)`` at the end of the step for the coordinates ``qn`` (Eqs 50-51)."""
        s = self.scheme
        acc = s.c0 * (qn - self.qi) + self.acc0
        return acc, self.vel0 + s.dt * s.delta * acc

    def residual(self, z: Array) -> Array:
        """The dynamics and the stabilised constraint at ``z = (q, lam)`` of the step's end."""
        s, t = self.scheme, self.t
        p, n, m = s.problem, s.n, s.m
        qn, ln = z[:n], z[n:]
        acc, vel = self.states(qn)
        Pq_ = np.asarray(p.phi_q(qn, t), float).reshape(m, n)
        r1 = (
            np.asarray(p.mass(qn, t), float) @ acc
            + Pq_.T @ ln
            - np.asarray(p.force(qn, vel, t), float)
        )
        if s.feedback == "explicit":
            fb = self.fb_old
        else:
            p_, pd_ = s.violations(qn, vel, t)
            fb = 2 * s.gamma * pd_ + s.kb * p_
        r2 = Pq_ @ acc - np.asarray(p.h(qn, vel, t), float) + fb
        return np.concatenate([r1, r2])

    def newton_matrix(self, z: Array, r: Array) -> Array:
        """The Newton matrix at ``z`` (module docstring), or finite differences of the residual."""
        s, t = self.scheme, self.t
        if s.use_fd:
            return _fd_jac(self.residual, z, r)
        p, n, m, c0, c1 = s.problem, s.n, s.m, s.c0, s.c1
        # has_tangents was checked when the scheme was chosen
        force_q, force_qd, h_q, h_qd = p.force_q, p.force_qd, p.h_q, p.h_qd
        if force_q is None or force_qd is None or h_q is None or h_qd is None:
            raise ValueError("the problem gives no tangents; use jacobian='fd'")
        qn = z[:n]
        acc, vel = self.states(qn)
        J = np.zeros((n + m, n + m))
        Pq_ = np.asarray(p.phi_q(qn, t), float).reshape(m, n)
        J[:n, :n] = (
            c0 * np.asarray(p.mass(qn, t), float)
            - np.asarray(force_q(qn, vel, t), float)
            - c1 * np.asarray(force_qd(qn, vel, t), float)
        )
        J[:n, n:] = Pq_.T
        hq = np.asarray(h_q(qn, vel, t), float).reshape(m, n)
        hqd = np.asarray(h_qd(qn, vel, t), float).reshape(m, n)
        J[n:, :n] = c0 * Pq_ - hq - c1 * hqd
        if s.feedback == "implicit":  # d(Phidot)/dq at fixed qd equals -h_qd / 2
            J[n:, :n] += 2 * s.gamma * (c1 * Pq_ - 0.5 * hqd) + s.kb * Pq_
        return J

    def solve(
        self, k: int, lam: Array, newton_tol: float, max_iterations: int
    ) -> tuple[Array, Array, int]:
        """``(q, lam, iterations)`` at the end of step ``k``: a constant-acceleration guess,
        then Newton on ``(q, lam)``."""
        s, t, n, dt = self.scheme, self.t, self.scheme.n, self.scheme.dt
        z = np.concatenate([self.qi + dt * self.qdi + 0.5 * dt * dt * self.qddi, lam])
        its, converged, size = 0, False, np.inf
        while its < max_iterations:
            its += 1
            r = self.residual(z)
            try:
                dz = np.linalg.solve(self.newton_matrix(z, r), -r)
            except np.linalg.LinAlgError as exc:
                raise NewtonConvergenceError(
                    f"singular Newton matrix at step {k} (t = {t:.6g} s, dt = {dt:.3g} s)"
                ) from exc
            z = z + dz
            size = np.max(np.abs(dz[:n]))
            if not np.all(np.isfinite(z)):
                break
            if s.problem.linear and not s.use_fd:
                converged = True
                break
            if size <= newton_tol * (1.0 + np.max(np.abs(z[:n]))):
                converged = True
                break
        if not converged:
            raise NewtonConvergenceError(
                f"Newton iteration did not converge at step {k} (t = {t:.6g} s, "
                f"dt = {dt:.3g} s) after {its} iterations: max|dq| = {size:.3g}, "
                f"tol = {newton_tol:.3g}"
            )
        return z[:n], z[n:], its


def simulate(
    problem: DAEProblem,
    q0: Any,
    qd0: Any,
    t_end: float,
    dt: float,
    *,
    t0: float = 0.0,
    gamma: float = 5.0,
    beta: float = 5.0,
    alpha: float = 0.25,
    delta: float = 0.5,
    feedback: Literal["explicit", "implicit"] = "explicit",
    baumgarte_form: Literal["eq49", "eq54_printed"] = "eq49",
    jacobian: Literal["auto", "tangent", "fd"] = "auto",
    newton_tol: float = 1e-10,
    max_iterations: int = 20,
    max_violation: float = 1e-2,
    max_velocity_violation: float | None = None,
) -> DAEResult:
    """Integrate a :class:`DAEProblem` from ``t0`` to ``t_end`` with Newmark + Baumgarte.

    Parameters
    ----------
    q0, qd0
        Initial state; should satisfy ``Phi = 0`` and ``Phidot = 0`` (a violation is
        damped by the Baumgarte terms, not removed).
    t_end, dt
        End time and maximal step, s; the step is ``(t_end - t0) / N`` with the
        smallest N giving a step <= dt.
    gamma, beta
        Baumgarte parameters, 1/s (Eq 49; paper: 5).
    alpha, delta
        Newmark parameters (0.25, 0.5: trapezoidal rule; 0.3025, 0.6: damped).
    feedback, baumgarte_form
        See the module docstring.
    jacobian
        ``"tangent"`` uses the problem's tangents, ``"fd"`` finite-differences the
        whole step residual, ``"auto"`` picks tangents when all are given.
    newton_tol, max_iterations
        Newton stops when ``max|dq| <= newton_tol (1 + max|q|)``.
    max_violation, max_velocity_violation
        Bounds on ``max|Phi|`` and ``max|Phidot|`` (None: only finiteness).

    Raises
    ------
    NewtonConvergenceError
        Newton failed or the Newton matrix was singular (names time and step).
    ConstraintViolationError
        A violation exceeded its bound or became non-finite (names time, step
        size, gamma/beta and the violation).
    """
    _check_settings(problem, (t0, t_end, dt), (alpha, delta), feedback, baumgarte_form, jacobian)
    n = problem.n_q
    n_steps = max(1, int(np.ceil((t_end - t0) / dt - 1e-9)))
    scheme = _Newmark(
        problem,
        dt=(t_end - t0) / n_steps,
        alpha=alpha,
        delta=delta,
        gamma=gamma,
        beta=beta,
        baumgarte_form=baumgarte_form,
        feedback=feedback,
        use_fd=jacobian == "fd" or (jacobian == "auto" and not problem.has_tangents),
    )
    return scheme.run(
        np.asarray(q0, dtype=float).reshape(n).copy(),
        np.asarray(qd0, dtype=float).reshape(n).copy(),
        t0 + scheme.dt * np.arange(n_steps + 1, dtype=np.float64),
        newton=(newton_tol, max_iterations),
        bounds=(max_violation, max_velocity_violation),
        labels=f"gamma = {gamma:g}, beta = {beta:g}, form = {baumgarte_form}, "
        f"feedback = {feedback}",
    )


def _check_settings(
    problem: DAEProblem,
    times: tuple[float, float, float],
    newmark: tuple[float, float],
    feedback: str,
    baumgarte_form: str,
    jacobian: str,
) -> None:
    """Refuse settings :func:`simulate` cannot run with (``ValueError`` naming them)."""
    (t0, t_end, dt), (alpha, delta) = times, newmark
    if not (0 < alpha and 0 < delta and dt > 0 and t_end > t0):
        raise ValueError(
            f"need alpha, delta, dt > 0 and t_end > t0; got alpha={alpha}, "
            f"delta={delta}, dt={dt}, t0={t0}, t_end={t_end}"
        )
    if feedback not in ("explicit", "implicit") or baumgarte_form not in ("eq49", "eq54_printed"):
        raise ValueError(f"unknown feedback={feedback!r} or baumgarte_form={baumgarte_form!r}")
    if jacobian == "tangent" and not problem.has_tangents:
        raise ValueError("jacobian='tangent' needs force_q, force_qd, h_q and h_qd")
