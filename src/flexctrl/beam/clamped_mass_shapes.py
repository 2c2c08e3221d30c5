"""One clamped-mass mode from its root: shape, derivatives, end values and integrals.

A mode is ``(lam, c1, c2, tail)``: for ``lam >= 3`` the stable form ``phi = c1 sin + c2 cos +
r e^{lam (xi-1)} + s e^{-lam xi}``, below 3 the Krylov series ``phi = A K2 + B K3``
(:mod:`.clamped_mass` derives both and the exact integrals).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from flexctrl.beam.clamped_mass_roots import INV_FACTORIAL, K_POWERS, SERIES_MAX

Array = NDArray[np.float64]


def krylov_series(lam: float, xi: Array, m: int) -> Array:
    """Krylov series ``K_m(xi) = sum_k lam^{4k} xi^{4k+m} / (4k+m)!``; ``K_{-1} = lam^4 K_3``.

    Parameters
    ----------
    lam : float
        ``beta L``, dimensionless.
    xi : numpy.ndarray
        Positions along the link over its length, dimensionless.
    m : int
        Index of the series, ``m >= -1``.

    Returns
    -------
    numpy.ndarray
        ``K_m`` at ``xi``.
    """
    if m < 0:
        return lam**4 * krylov_series(lam, xi, m + 4)
    return np.power.outer(xi, (K_POWERS + m).astype(float)) @ (
        lam**K_POWERS * INV_FACTORIAL[K_POWERS + m]
    )


def _ksum(lam: float, m: int, p: int = 0) -> float:
    """``int_0^1 xi^p K_m dxi`` term by term."""
    return float(np.sum(lam**K_POWERS * INV_FACTORIAL[K_POWERS + m] / (K_POWERS + m + p + 1)))


def krylov_coefficients(lam: float, c1: float, c2: float) -> tuple[float, float]:
    """``(A, B)`` with ``phi = A K_2 + B K_3``.

    Parameters
    ----------
    lam : float
        The mode's root ``beta L``, dimensionless.
    c1, c2 : float
        The mode's coefficients (module docstring).

    Returns
    -------
    tuple of float
        The Krylov coefficients.
    """
    return -2.0 * lam**2 * c2, -2.0 * lam**3 * c1


def mode_derivative(lam: float, c1: float, c2: float, tail: float, xi: Array, d: int) -> Array:
    """``d``-th ``xi``-derivative of one mode at ``xi``.

    Parameters
    ----------
    lam : float
        The mode's root ``beta L``, dimensionless.
    c1, c2, tail : float
        The mode's coefficients (module docstring).
    xi : numpy.ndarray
        Positions over the link's length, dimensionless.
    d : int
        Order of the derivative, 0 to 3.

    Returns
    -------
    numpy.ndarray
        The derivative at ``xi``.
    """
    if lam < SERIES_MAX:
        a, b = krylov_coefficients(lam, c1, c2)
        return a * krylov_series(lam, xi, 2 - d) + b * krylov_series(lam, xi, 3 - d)
    s = c1 + tail * math.exp(-lam)
    ts, tc = [(c1, c2), (-c2, c1), (-c1, -c2), (c2, -c1)][d]
    return lam**d * (
        ts * np.sin(lam * xi)
        + tc * np.cos(lam * xi)
        + tail * np.exp(lam * (xi - 1.0))
        + (-1) ** d * s * np.exp(-lam * xi)
    )


def end_values(lam: float, c1: float, c2: float, tail: float) -> Array:
    """``[[phi, phi', phi'', phi''']`` at ``xi = 0``, same at ``xi = 1]``.

    Parameters
    ----------
    lam : float
        The mode's root ``beta L``, dimensionless.
    c1, c2, tail : float
        The mode's coefficients (module docstring).

    Returns
    -------
    numpy.ndarray
        Shape (2, 4).
    """
    xi = np.array([0.0, 1.0])
    return np.array([mode_derivative(lam, c1, c2, tail, xi, d) for d in range(4)]).T


def _null(rows: Array, units: tuple[float, float], weight: Array) -> Array:
    """Unit ``n`` minimising the work norm of the tip-condition residual ``rows @ n``.

    ``rows`` are the ``phi''`` and ``phi'''`` residuals in ``units``; as a tip force
    ``f = (phi''', -phi'')`` they do work ``f . u_k`` on another mode's tip displacement
    ``u_k`` (Lagrange identity), and ``u_k`` is bounded by ``u^T weight u <~ 1``.  So
    ``n`` minimises ``f^T weight^-1 f``: the rounding error of ``lam`` goes where it
    spoils Eq 40 least.
    """
    force = np.array([[0.0, units[1]], [-units[0], 0.0]]) @ rows
    ev, vec = np.linalg.eigh(weight)
    return np.linalg.svd((vec / np.sqrt(ev)).T @ force)[2][-1]


def raw_mode(lam: float, mu: float, eta: float, kappa: float) -> tuple[float, float, float]:
    """Unnormalised ``(c1, c2, tail)`` satisfying the tip conditions at root ``lam``.

    Parameters
    ----------
    lam : float
        A root ``beta L`` of the frequency equation, dimensionless.
    mu, eta, kappa : float
        Tip mass, inertia and first moment, ``m_D / (rho L)``, ``J_D / (rho L^3)``,
        ``M_D / (rho L^2)``, dimensionless.

    Returns
    -------
    tuple of float
        ``(c1, c2, tail)``.
    """
    ev, vec = np.linalg.eigh(np.array([[mu, kappa], [kappa, eta]]))
    weight = (vec * np.abs(ev)) @ vec.T + np.diag([0.25, 0.25 / max(lam, 1.0) ** 2])
    l4 = lam**4
    if lam < SERIES_MAX:  # phi'' and phi''' residuals over (A, B), phi = A K2 + B K3
        k0, k1, k2, k3 = (float(krylov_series(lam, np.ones(1), m)[0]) for m in range(4))
        rows = np.array(
            [
                [k0 - l4 * (eta * k1 + kappa * k2), k1 - l4 * (eta * k2 + kappa * k3)],
                [l4 * (k3 + mu * k2 + kappa * k1), k0 + l4 * (mu * k3 + kappa * k2)],
            ]
        )
        a, b = _null(rows, (1.0, 1.0), weight)
        c1, c2 = -b / (2.0 * lam**3), -a / (2.0 * lam**2)
        return c1, c2, -0.5 * (c1 + c2) * math.exp(lam)
    c, s, e = math.cos(lam), math.sin(lam), math.exp(-lam)
    # (phi, phi'/lam, phi''/lam^2, phi'''/lam^3) at xi = 1 over (c1, tail)
    p = np.array(
        [
            [s - c + e, 1 - 2 * e * c + e * e],
            [c + s - e, 1 + 2 * e * s - e * e],
            [c - s + e, 1 + 2 * e * c + e * e],
            [-c - s - e, 1 - 2 * e * s - e * e],
        ]
    )
    g1, g2 = eta * lam**3, kappa * lam**2
    rows = np.array([p[2] - g1 * p[1] - g2 * p[0], p[3] + mu * lam * p[0] + g2 * p[1]])
    c1, tail = _null(rows, (lam**2, lam**3), weight)
    return c1, -c1 - 2.0 * tail * e, tail


def _pair_series(lj: float, abj: tuple[float, float], lk: float, abk: tuple[float, float]) -> float:
    """``int_0^1 phi_j phi_k`` for two Krylov-form modes (double series)."""
    den = K_POWERS[:, None] + K_POWERS[None, :]
    tot = 0.0
    for m, cm in zip((2, 3), abj):
        for n, cn in zip((2, 3), abk):
            terms = np.outer(
                lj**K_POWERS * INV_FACTORIAL[K_POWERS + m],
                lk**K_POWERS * INV_FACTORIAL[K_POWERS + n],
            )
            tot += cm * cn * float(np.sum(terms / (den + m + n + 1)))
    return tot


def mode_integrals(lam: float, c1: float, c2: float, tail: float) -> tuple[float, float, float]:
    """``int phi``, ``int xi phi`` and ``int phi^2`` over ``0 <= xi <= 1``.

    Parameters
    ----------
    lam : float
        The mode's root ``beta L``, dimensionless.
    c1, c2, tail : float
        The mode's coefficients (module docstring).

    Returns
    -------
    tuple of float
        The three integrals, dimensionless.
    """
    if lam < SERIES_MAX:
        a, b = krylov_coefficients(lam, c1, c2)
        return (
            a * _ksum(lam, 2) + b * _ksum(lam, 3),
            a * _ksum(lam, 2, 1) + b * _ksum(lam, 3, 1),
            _pair_series(lam, (a, b), lam, (a, b)),
        )
    (_, _, f2, f3), (g0, g1, g2, g3) = end_values(lam, c1, c2, tail)
    l4 = lam**4
    sq = (3 * g0 * g3 - g1 * g2 + l4 * g0 * g0 - 2 * g1 * g3 + g2 * g2) / (4 * l4)
    return (g3 - f3) / l4, (g3 - g2 + f2) / l4, sq


def cross_integral(lj: float, mj: tuple, gj: Array, lk: float, mk: tuple, gk: Array) -> float:
    """``int_0^1 phi_j phi_k`` for distinct roots.

    Parameters
    ----------
    lj, lk : float
        The two modes' roots ``beta L``, dimensionless.
    mj, mk : tuple
        The two modes' ``(c1, c2, tail)``.
    gj, gk : numpy.ndarray
        The two modes' derivatives 0..3 at ``xi = 1``.

    Returns
    -------
    float
        The integral, dimensionless.
    """
    if lj < SERIES_MAX and lk < SERIES_MAX:
        return _pair_series(
            lj, krylov_coefficients(lj, *mj[:2]), lk, krylov_coefficients(lk, *mk[:2])
        )
    lagrange = gj[3] * gk[0] - gj[2] * gk[1] + gj[1] * gk[2] - gj[0] * gk[3]
    return lagrange / (lj**4 - lk**4)
