"""The frequency equation of the clamped-mass beam and its roots (:mod:`.clamped_mass`).

``Delta(lam)`` scaled to be pole-free and bounded (:func:`frequency_determinant`), evaluated by
power series below ``lam = 3``; its roots isolated by an exact eigenvalue count
(Wittrick-Williams, :func:`eigenvalue_count`) and polished by brentq
(:func:`frequency_roots`).  The module docstring of :mod:`.clamped_mass` derives both.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq

from flexctrl.errors import SolverError

Array = NDArray[np.float64]
SERIES_MAX = 3.0  # lam below which power series are used
SERIES_TERMS = 12  # series terms (lam^{4k}/(4k)! < 1e-30 at lam = 3, k = 12)
K_POWERS = 4 * np.arange(SERIES_TERMS)
INV_FACTORIAL = np.array([1.0 / math.factorial(i) for i in range(4 * SERIES_TERMS + 8)])


def _combos(lam: float) -> tuple[float, float, float, float, float]:
    """``(1 + cC, cS - sC, cS + sC, sS, 1 - cC) / cosh(lam)`` without cancellation."""
    if lam < SERIES_MAX:
        u, t, sums = -4.0 * lam**4, 1.0, [0.0, 0.0, 0.0, 0.0]
        for k in range(SERIES_TERMS):
            for m in range(4):
                sums[m] += t * INV_FACTORIAL[4 * k + m]
            t *= u
        ch, omc = math.cosh(lam), 1.0 - sums[0]
        if lam < 1.5:  # 1 - cC ~ lam^4/6: sum it without the k = 0 term
            omc, t = 0.0, -u
            for k in range(1, SERIES_TERMS):
                omc += t * INV_FACTORIAL[4 * k]
                t *= u
        return (
            (1.0 + sums[0]) / ch,
            -4.0 * lam**3 * sums[3] / ch,
            2.0 * lam * sums[1] / ch,
            2.0 * lam**2 * sums[2] / ch,
            omc / ch,
        )
    c, s, th, e = math.cos(lam), math.sin(lam), math.tanh(lam), math.exp(-lam)
    sech = 2.0 * e / (1.0 + e * e)
    return sech + c, c * th - s, c * th + s, s * th, sech - c


def _delta_parts(
    lam: float, mu: float, eta: float, kappa: float
) -> tuple[float, float, float, float]:
    e1, e2, e3, e4, e5 = _combos(lam)
    d, l2 = mu * eta - kappa * kappa, lam * lam
    num = e1 + mu * lam * e2 - eta * lam * l2 * e3 - 2.0 * kappa * l2 * e4 + d * l2 * l2 * e5
    w = 1.0 + mu * lam + 2.0 * abs(kappa) * l2 + eta * lam * l2 + abs(d) * l2 * l2
    return num / w, e2, e3, e5


def delta(lam: float, mu: float, eta: float, kappa: float) -> float:
    """The scaled characteristic function at one ``lam`` (:func:`frequency_determinant`).

    Parameters
    ----------
    lam : float
        ``beta L``, dimensionless, >= 0.
    mu, eta, kappa : float
        Tip mass, inertia and first moment, ``m_D / (rho L)``, ``J_D / (rho L^3)``,
        ``M_D / (rho L^2)``, dimensionless.

    Returns
    -------
    float
        ``Delta(lam) / (cosh(lam) W(lam))``, at most 2 in magnitude.
    """
    return _delta_parts(lam, mu, eta, kappa)[0]


def eigenvalue_count(lam: float, mu: float, eta: float, kappa: float) -> int:
    """Number of eigenvalues (``omega^2 > 0``) strictly below ``lam`` (Wittrick-Williams).

    Parameters
    ----------
    lam : float
        ``beta L``, dimensionless.
    mu, eta, kappa : float
        Tip mass, inertia and first moment, ``m_D / (rho L)``, ``J_D / (rho L^3)``,
        ``M_D / (rho L^2)``, dimensionless.

    Returns
    -------
    int
        The count of roots ``beta_j L < lam``.
    """
    if lam <= 0.0:
        return 0
    f, e2, e3, e5 = _delta_parts(lam, mu, eta, kappa)
    j0 = 0  # clamped-clamped roots below lam; sign(cos - sech) = -sign(e5)
    if lam > math.pi:
        k = int(lam // math.pi)
        j0 = k - 1 + (1 if e5 * (-1) ** k > 0.0 else 0)
    e5 = e5 if e5 != 0.0 else 1e-300
    trace = (lam**3 * e3 - lam * e2) / e5 - lam**4 * (mu + eta)  # of Kb - lam^4 T
    det = f if e5 > 0.0 else -f  # has the sign of det(Kb - lam^4 T)
    if det < 0.0:
        return j0 + 1
    return j0 + (0 if trace >= 0.0 else 2 if det > 0.0 else 1)


def frequency_roots(n: int, mu: float, eta: float, kappa: float) -> list[float]:
    """First ``n`` positive roots of ``Delta``, ascending, isolated by counting.

    Parameters
    ----------
    n : int
        Number of roots.
    mu, eta, kappa : float
        Tip mass, inertia and first moment, ``m_D / (rho L)``, ``J_D / (rho L^3)``,
        ``M_D / (rho L^2)``, dimensionless.

    Returns
    -------
    list of float
        ``beta_j L``, dimensionless.
    """
    if n == 0:
        return []
    hi = (n - 0.5) * math.pi + 0.5  # above the n-th clamped-free root, a bound if T >= 0
    n_hi = eigenvalue_count(hi, mu, eta, kappa)
    for _ in range(1000):  # an indefinite T can raise frequencies
        if n_hi >= n:
            break
        hi += math.pi
        n_hi = eigenvalue_count(hi, mu, eta, kappa)
    else:
        raise SolverError(f"could not bracket {n} roots (mu={mu}, eta={eta}, kappa={kappa})")
    roots: list[float] = []
    stack = [(0.0, hi, 0, n_hi)]
    while stack:
        a, b, na, nb = stack.pop()
        if na >= n or nb == na:
            continue
        if nb - na == 1:
            roots.append(_polish(a, b, na, mu, eta, kappa))
        elif b - a <= 4e-16 * b:  # a multiple eigenvalue
            roots.extend([0.5 * (a + b)] * (nb - na))
        else:
            m = 0.5 * (a + b)
            nm = eigenvalue_count(m, mu, eta, kappa)
            stack += [(m, b, nm, nb), (a, m, na, nm)]
    return sorted(roots)[:n]


#: brentq's relative tolerance on a root ``lam`` (4 eps, the smallest it accepts).
ROOT_RTOL = 8.9e-16


def _polish(a: float, b: float, na: int, mu: float, eta: float, kappa: float) -> float:
    """The single eigenvalue in ``[a, b)``: brentq on the sign change, else count-bisection."""
    fa, fb = delta(a, mu, eta, kappa), delta(b, mu, eta, kappa)
    if fa == 0.0:
        return a
    if fa * fb < 0.0:
        return brentq(delta, a, b, args=(mu, eta, kappa), xtol=1e-300, rtol=ROOT_RTOL)
    while b - a > 4e-16 * b:  # no sign change seen (root within rounding of b)
        m = 0.5 * (a + b)
        if eigenvalue_count(m, mu, eta, kappa) > na:
            b = m
        else:
            a = m
    return 0.5 * (a + b)


def frequency_determinant(lam: ArrayLike, mu: float, eta: float, kappa: float) -> float | Array:
    """Scaled characteristic function of the clamped-mass beam.

    ``Delta(lam) / (cosh(lam) W(lam))`` with ``Delta`` and ``W > 0`` as in the module
    docstring; its positive zeros are ``beta_j L``.  Bounded by 2 in magnitude.

    Parameters
    ----------
    lam
        ``beta L``, dimensionless, >= 0 (scalar or array).
    mu, eta, kappa
        ``m_D / (rho L)``, ``J_D / (rho L^3)``, ``M_D / (rho L^2)``, dimensionless.

    Returns
    -------
    float or ndarray shaped like ``lam``
    """
    for name, val in (("mu", mu), ("eta", eta), ("kappa", kappa)):
        if not math.isfinite(float(val)):
            raise ValueError(f"{name} must be finite, got {val!r}")
    la = np.asarray(lam, dtype=float)
    if not np.all(la >= 0.0) or not np.all(np.isfinite(la)):
        raise ValueError(f"lam must be finite and >= 0, got {lam!r}")
    f = np.vectorize(lambda x: delta(float(x), float(mu), float(eta), float(kappa)), otypes=[float])
    out = f(la)
    return float(out) if out.ndim == 0 else out
