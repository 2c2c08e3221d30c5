"""The discrete algebraic Riccati equation by the structure-preserving doubling algorithm (SDA).

Why not the Schur method (``scipy.linalg.solve_discrete_are``, ``control.dlqe``)
alone: the Kalman-filter DARE of a flexible arm is a symplectic pencil whose
eigenvalues spread over many decades (heavily damped local modes of the light hubs
at ``|z| ~ 0.06``, their reciprocals at ~17, and, in a horizontal plane, three
Jordan blocks of the free rigid-body double integrators at ``z = 1``) while the
process noise is rank-deficient.  The QZ *reordering* step is then ill-conditioned
and fails or succeeds with round-off, whatever diagonal scaling is applied first,
although the solution itself is well conditioned.

SDA (Chu, Fan, Lin and Wang, "Structure-preserving algorithms for periodic discrete-time
algebraic Riccati equations", Int. J. Control 77, 2004; for the time-invariant case
e.g. Huang, Li and Lin, "Structure-Preserving Doubling Algorithms for Nonlinear
Matrix Equations", SIAM 2018, ch. 3) needs no eigenvalue reordering.  For
``X = A'XA - A'XB (R + B'XB)^-1 B'XA + Q`` start from ``A_0 = A``, ``G_0 = B R^-1 B'``,
``H_0 = Q`` and iterate::

    W     = I + G_k H_k
    A_k+1 = A_k W^-1 A_k
    G_k+1 = G_k + A_k W^-1 G_k A_k'
    H_k+1 = H_k + A_k' H_k W^-1 A_k

``H_k`` converges quadratically to the stabilising solution whenever it exists; the
error falls like ``rho^(2^k)`` with ``rho`` the closed-loop spectral radius (ten
iterations at ``rho = 0.94``).  One Newton (Kleinman) step then refines the solution (its
round-off grows with ``||A||``, large in physical units), and every solution is checked
(finite, symmetric, residual, closed loop strictly stable); a failure is a
:class:`~flexctrl.errors.SolverError`.
"""

from __future__ import annotations

import numpy as np

from flexctrl.errors import SolverError

#: Largest relative DARE residual ``||res||_F / max(1, ||X||_F)`` accepted.
RESIDUAL_TOL = 1e-8


def _doubling(
    Ak: np.ndarray,
    Gk: np.ndarray,
    Hk: np.ndarray,
    eye: np.ndarray,
    tol: float,
    max_iter: int,
    what: str,
) -> np.ndarray:
    """The SDA iteration from ``(A_0, G_0, H_0)``; returns the converged ``H``."""
    for _ in range(max_iter):
        W = eye + Gk @ Hk
        try:
            V_A = np.linalg.solve(W, Ak)
            V_G = np.linalg.solve(W, Gk)
        except np.linalg.LinAlgError as exc:
            raise SolverError(
                f"{what}: the doubling iteration met a singular matrix ({exc})"
            ) from exc
        H_next = Hk + V_A.T @ Hk @ Ak
        G_next = Gk + Ak @ V_G @ Ak.T
        Ak = Ak @ V_A
        H_next = 0.5 * (H_next + H_next.T)
        if not np.all(np.isfinite(H_next)):
            raise SolverError(
                f"{what}: the doubling iteration diverged (no stabilising solution: "
                "an uncontrollable/unobservable mode on or outside the unit circle?)"
            )
        change = np.linalg.norm(H_next - Hk, 1)
        Hk, Gk = H_next, 0.5 * (G_next + G_next.T)
        if change <= tol * max(1.0, float(np.linalg.norm(Hk, 1))):
            return Hk
    raise SolverError(f"{what}: the doubling iteration did not converge in {max_iter} steps")


def _residual(A, B, Q, R, X) -> float:
    """The relative DARE residual ``||res||_F / max(1, ||X||_F)`` of ``X``."""
    S = R + B.T @ X @ B
    residual = A.T @ X @ A - A.T @ X @ B @ np.linalg.solve(S, B.T @ X @ A) + Q - X
    return float(np.linalg.norm(residual)) / max(1.0, float(np.linalg.norm(X)))


def _refined(A, B, Q, R, X) -> tuple[np.ndarray, float]:
    """``X`` after one Newton (Kleinman) step, if that lowers its residual, and the residual.

    With a flexible arm's physical units (``||A||`` 1e3-1e5: stiff modes in metres) the
    doubling's round-off leaves ``X`` accurate to about 1e-7 and its residual near 1e-10; the
    Newton step, the Stein equation ``Ac' X Ac - X + Q + K'RK = 0`` of the closed loop ``Ac``
    (Bartels-Stewart, no eigenvalue reordering), brings the residual to about 1e-12, so the
    check below fails a wrong solution, not the round-off of a right one.
    """
    from scipy.linalg import solve_discrete_lyapunov

    before = _residual(A, B, Q, R, X)
    K = np.linalg.solve(R + B.T @ X @ B, B.T @ X @ A)
    closed = A - B @ K
    with np.errstate(all="ignore"):
        try:
            step = solve_discrete_lyapunov(closed.T, Q + K.T @ R @ K)
        except (np.linalg.LinAlgError, ValueError):
            return X, before
    step = 0.5 * (step + step.T)
    if not np.all(np.isfinite(step)):
        return X, before
    after = _residual(A, B, Q, R, step)
    return (step, after) if after < before else (X, before)


def solve_dare(
    A: np.ndarray,
    B: np.ndarray,
    Q: np.ndarray,
    R: np.ndarray,
    *,
    tol: float = 1e-14,
    max_iter: int = 200,
    what: str = "DARE",
) -> np.ndarray:
    """Stabilizing solution ``X`` of ``X = A'XA - A'XB (R + B'XB)^-1 B'XA + Q`` (SDA).

    See the module docstring for the method.

    Parameters
    ----------
    A : (n, n) ndarray
        The state matrix.
    B : (n, m) ndarray
        The input matrix.
    Q : (n, n) ndarray
        Symmetric positive semidefinite.
    R : (m, m) ndarray
        Symmetric positive definite.
    tol : float
        Stop when the change of ``H_k`` is below ``tol`` relative to its norm.
    max_iter : int
        Doubling steps (each squares the closed-loop contraction).
    what : str
        Name used in error messages (e.g. "LQR", "Kalman filter").

    Returns
    -------
    ndarray
        ``X``, symmetric.

    Raises
    ------
    SolverError
        No convergence, a non-finite or non-stabilising result, or a residual above
        :data:`RESIDUAL_TOL`.
    """
    A, B, Q, R = (np.asarray(M, dtype=float) for M in (A, B, Q, R))
    n = A.shape[0]
    eye = np.eye(n)
    Ak = A.copy()
    Gk = B @ np.linalg.solve(0.5 * (R + R.T), B.T)
    Gk = 0.5 * (Gk + Gk.T)
    Hk = 0.5 * (Q + Q.T)
    # divergence is detected in the iteration, as a non-finite H_k
    with np.errstate(over="ignore", invalid="ignore"):
        Hk = _doubling(Ak, Gk, Hk, eye, tol, max_iter, what)
    X, rel = _refined(A, B, Q, R, Hk)
    if rel > RESIDUAL_TOL:
        raise SolverError(f"{what}: Riccati residual {rel:.3g} above {RESIDUAL_TOL:g}")
    K = np.linalg.solve(R + B.T @ X @ B, B.T @ X @ A)
    rho = float(np.max(np.abs(np.linalg.eigvals(A - B @ K))))
    if not rho < 1.0:
        raise SolverError(
            f"{what}: the Riccati solution does not stabilise (closed-loop spectral radius "
            f"{rho:.6g})"
        )
    return X


def lqr_gain(
    Ad: np.ndarray, Bd: np.ndarray, Q: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Discrete LQR gain ``K`` (``u = -K x``) and DARE solution ``S``.

    The DARE is solved by doubling (:func:`flexctrl.control.riccati.solve_dare`), which
    needs no eigenvalue reordering and so does not fail on the ill-conditioned pencils of
    flexible arms.

    Parameters
    ----------
    Ad, Bd : ndarray
        The discrete system.
    Q, R : ndarray
        State and input weights.

    Returns
    -------
    tuple of ndarray
        ``(K, S)``.

    Raises
    ------
    SolverError
        When no stabilizing solution is found.
    """
    S = solve_dare(Ad, Bd, Q, R, what="LQR")
    K = np.linalg.solve(R + Bd.T @ S @ Bd, Bd.T @ S @ Ad)
    return K, S


__all__ = ["solve_dare", "lqr_gain", "RESIDUAL_TOL"]
