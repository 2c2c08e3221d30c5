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
    """``M(q,t) qdd + Phi_q^T lam = f(q,qd,t)``, ``Phi(q,t) = 0`` as callables returning numpy
    arrays.

    ``mass(q,t)`` (n,n); ``force(q,qd,t)`` (n,); ``phi(q,t)``, ``phi_t(q,t)`` (m,);
    ``phi_q(q,t)`` (m,n); ``h(q,qd,t)`` (m,), the right side of ``Phi_q qdd = h``
    (Eq 47).  Optional tangents ``force_q``, ``force_qd`` (n,n) and ``h_q``,
    ``h_qd`` (m,n) give the Newton matrix directly; without all four it is formed
    by finite differences.  ``linear=True`` promises that M and Phi_q do not depend
    on q and that f and h are affine in (q, qd) with exact tangents.
    See :func:`casadi_problem` for building one from CasADi expressions.
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
    if not (0 < alpha and 0 < delta and dt > 0 and t_end > t0):
        raise ValueError(
            f"need alpha, delta, dt > 0 and t_end > t0; got alpha={alpha}, "
            f"delta={delta}, dt={dt}, t0={t0}, t_end={t_end}"
        )
    if feedback not in ("explicit", "implicit") or baumgarte_form not in ("eq49", "eq54_printed"):
        raise ValueError(f"unknown feedback={feedback!r} or baumgarte_form={baumgarte_form!r}")
    if jacobian == "tangent" and not problem.has_tangents:
        raise ValueError("jacobian='tangent' needs force_q, force_qd, h_q and h_qd")
    use_fd = jacobian == "fd" or (jacobian == "auto" and not problem.has_tangents)
    n, m = problem.n_q, problem.n_c
    n_steps = max(1, int(np.ceil((t_end - t0) / dt - 1e-9)))
    dt = (t_end - t0) / n_steps
    c0, c1 = 1.0 / (alpha * dt * dt), delta / (alpha * dt)
    kb = -(beta**2) if baumgarte_form == "eq54_printed" else beta**2
    tgrid = t0 + dt * np.arange(n_steps + 1)

    def violations(q: Array, qd: Array, t: float) -> tuple[Array, Array]:
        return (
            np.asarray(problem.phi(q, t), float),
            np.asarray(problem.phi_q(q, t), float) @ qd + np.asarray(problem.phi_t(q, t), float),
        )

    q = np.asarray(q0, dtype=float).reshape(n).copy()
    qd = np.asarray(qd0, dtype=float).reshape(n).copy()
    Q, QD, QDD = (np.empty((n_steps + 1, n)) for _ in range(3))
    LAM = np.empty((n_steps + 1, m))
    VP, VV = np.zeros(n_steps + 1), np.zeros(n_steps + 1)
    ITS = np.zeros(n_steps + 1, dtype=int)
    start = time.perf_counter()
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        # Consistent initial accelerations and multipliers (Eqs 55-56).
        phi, phid = violations(q, qd, t0)
        A = np.zeros((n + m, n + m))
        A[:n, :n] = problem.mass(q, t0)
        Pq = np.asarray(problem.phi_q(q, t0), float).reshape(m, n)
        A[:n, n:], A[n:, :n] = Pq.T, Pq
        rhs = np.concatenate(
            [
                np.asarray(problem.force(q, qd, t0), float),
                np.asarray(problem.h(q, qd, t0), float) - 2 * gamma * phid - kb * phi,
            ]
        )
        try:
            sol = np.linalg.solve(A, rhs)
        except np.linalg.LinAlgError as exc:
            raise NewtonConvergenceError(
                f"singular augmented matrix for the initial accelerations at "
                f"t = {t0:g} s (dependent constraints?)"
            ) from exc
        qdd, lam = sol[:n], sol[n:]
        Q[0], QD[0], QDD[0], LAM[0] = q, qd, qdd, lam
        VP[0] = np.max(np.abs(phi), initial=0.0)
        VV[0] = np.max(np.abs(phid), initial=0.0)

        for k in range(1, n_steps + 1):
            t = tgrid[k]
            qi, qdi, qddi = q, qd, qdd
            acc0 = -qdi / (alpha * dt) - (0.5 / alpha - 1.0) * qddi
            vel0 = qdi + dt * (1.0 - delta) * qddi
            fb_old = 2 * gamma * phid + kb * phi  # step-i violations (Eq 54)

            def states(qn: Array) -> tuple[Array, Array]:
                acc = c0 * (qn - qi) + acc0
                return acc, vel0 + dt * delta * acc

            def residual(z: Array) -> Array:
                qn, ln = z[:n], z[n:]
                acc, vel = states(qn)
                Pq_ = np.asarray(problem.phi_q(qn, t), float).reshape(m, n)
                r1 = (
                    np.asarray(problem.mass(qn, t), float) @ acc
                    + Pq_.T @ ln
                    - np.asarray(problem.force(qn, vel, t), float)
                )
                if feedback == "explicit":
                    fb = fb_old
                else:
                    p_, pd_ = violations(qn, vel, t)
                    fb = 2 * gamma * pd_ + kb * p_
                r2 = Pq_ @ acc - np.asarray(problem.h(qn, vel, t), float) + fb
                return np.concatenate([r1, r2])

            def newton_matrix(z: Array, r: Array) -> Array:
                if use_fd:
                    return _fd_jac(residual, z, r)
                qn = z[:n]
                acc, vel = states(qn)
                J = np.zeros((n + m, n + m))
                Pq_ = np.asarray(problem.phi_q(qn, t), float).reshape(m, n)
                J[:n, :n] = (
                    c0 * np.asarray(problem.mass(qn, t), float)
                    - np.asarray(problem.force_q(qn, vel, t), float)
                    - c1 * np.asarray(problem.force_qd(qn, vel, t), float)
                )
                J[:n, n:] = Pq_.T
                hq = np.asarray(problem.h_q(qn, vel, t), float).reshape(m, n)
                hqd = np.asarray(problem.h_qd(qn, vel, t), float).reshape(m, n)
                J[n:, :n] = c0 * Pq_ - hq - c1 * hqd
                if feedback == "implicit":  # d(Phidot)/dq at fixed qd equals -h_qd / 2
                    J[n:, :n] += 2 * gamma * (c1 * Pq_ - 0.5 * hqd) + kb * Pq_
                return J

            # Predictor: constant-acceleration guess, then Newton on (q, lam).
            z = np.concatenate([qi + dt * qdi + 0.5 * dt * dt * qddi, lam])
            its, converged, size = 0, False, np.inf
            while its < max_iterations:
                its += 1
                r = residual(z)
                try:
                    dz = np.linalg.solve(newton_matrix(z, r), -r)
                except np.linalg.LinAlgError as exc:
                    raise NewtonConvergenceError(
                        f"singular Newton matrix at step {k} (t = {t:.6g} s, dt = {dt:.3g} s)"
                    ) from exc
                z = z + dz
                size = np.max(np.abs(dz[:n]))
                if not np.all(np.isfinite(z)):
                    break
                if problem.linear and not use_fd:
                    converged = True
                    break
                if size <= newton_tol * (1.0 + np.max(np.abs(z[:n]))):
                    converged = True
                    break
            if not converged:
                raise NewtonConvergenceError(
                    f"Newton iteration did not converge at step {k} (t = {t:.6g} s, dt = "
                    f"{dt:.3g} s) "
                    f"after {its} iterations: max|dq| = {size:.3g}, tol = {newton_tol:.3g}"
                )
            q, lam = z[:n], z[n:]
            qdd, qd = states(q)
            phi, phid = violations(q, qd, t)
            vp = np.max(np.abs(phi), initial=0.0)
            vv = np.max(np.abs(phid), initial=0.0)
            bad_v = max_velocity_violation is not None and not vv <= max_velocity_violation
            if not (vp <= max_violation and np.isfinite(vv)) or bad_v or not np.all(np.isfinite(q)):
                raise ConstraintViolationError(
                    f"constraint violation grew without bound at step {k} (t = {t:.6g} s, "
                    f"dt = {dt:.3g} s, gamma = {gamma:g}, beta = {beta:g}, form = "
                    f"{baumgarte_form}, "
                    f"feedback = {feedback}): max|Phi| = {vp:.3g} (bound {max_violation:g}), "
                    f"max|Phidot| = {vv:.3g} (bound {max_velocity_violation})"
                )
            Q[k], QD[k], QDD[k], LAM[k], VP[k], VV[k], ITS[k] = q, qd, qdd, lam, vp, vv, its
    wall = time.perf_counter() - start
    return DAEResult(
        t=tgrid,
        q=Q,
        qd=QD,
        qdd=QDD,
        lam=LAM,
        phi_violation=VP,
        phidot_violation=VV,
        newton_iterations=ITS,
        wall_time=wall,
        dt=dt,
        gamma=float(gamma),
        beta=float(beta),
        alpha=float(alpha),
        delta=float(delta),
    )


def casadi_problem(
    q: Any, qd: Any, t: Any, mass: Any, force: Any, phi: Any, *, linear: bool = False
) -> DAEProblem:
    """Build a :class:`DAEProblem` from CasADi symbols and expressions.

    Parameters
    ----------
    q, qd, t
        CasADi ``SX``/``MX`` symbols (n x 1, n x 1, scalar).
    mass, force, phi
        Expressions for ``M(q,t)`` (n x n), ``f(q,qd,t)`` (n x 1), ``Phi(q,t)`` (m x 1, m
        may be 0).  ``Phi_q``, ``Phi_t``, ``h`` and all Newton tangents are derived by
        automatic differentiation, so the model supplies only M, f and Phi.
    """
    import casadi as ca

    n = int(q.numel())
    m = int(phi.numel())
    phi = ca.reshape(phi, m, 1)
    phi_q = ca.jacobian(phi, q)
    phi_t = ca.jacobian(phi, t)
    phidot = ca.mtimes(phi_q, qd) + phi_t
    h = -(ca.mtimes(ca.jacobian(phidot, q), qd) + ca.jacobian(phidot, t))
    funcs = {
        "mass": ca.Function("M", [q, t], [mass]),
        "phi": ca.Function("Phi", [q, t], [phi]),
        "phi_q": ca.Function("Phi_q", [q, t], [phi_q]),
        "phi_t": ca.Function("Phi_t", [q, t], [phi_t]),
        "force": ca.Function("f", [q, qd, t], [force]),
        "force_q": ca.Function("f_q", [q, qd, t], [ca.jacobian(force, q)]),
        "force_qd": ca.Function("f_qd", [q, qd, t], [ca.jacobian(force, qd)]),
        "h": ca.Function("h", [q, qd, t], [h]),
        "h_q": ca.Function("h_q", [q, qd, t], [ca.jacobian(h, q)]),
        "h_qd": ca.Function("h_qd", [q, qd, t], [ca.jacobian(h, qd)]),
    }
    shapes = {
        "mass": (n, n),
        "phi": (m,),
        "phi_q": (m, n),
        "phi_t": (m,),
        "force": (n,),
        "force_q": (n, n),
        "force_qd": (n, n),
        "h": (m,),
        "h_q": (m, n),
        "h_qd": (m, n),
    }

    def wrap(name: str) -> Callable[..., Array]:
        fun, shape = funcs[name], shapes[name]
        return lambda *args: np.asarray(fun(*args).full(), dtype=float).reshape(shape)

    return DAEProblem(n_q=n, n_c=m, linear=linear, **{k: wrap(k) for k in funcs})
