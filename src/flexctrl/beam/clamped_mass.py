"""Clamped-mass Euler-Bernoulli beam: frequencies, orthonormal modes, modal integrals.

Re-derived from Subedi et al. 2021 (Eqs 20-40, 50-53); SI units.  ``EI w'''' + rho w_tt
= 0``, ``w = phi(x) q(t)``, ``q'' = -omega^2 q``, ``beta^4 = rho omega^2 / EI``.  With
``xi = x/L``, ``lam = beta L``, ``mu = m_D/(rho L)``, ``eta = J_D/(rho L^3)``,
``kappa = M_D/(rho L^2)`` and ``' = d/dxi``, the tip conditions (Eqs 33-36) are::

    phi''(1) = lam^4 (eta phi'(1) + kappa phi(1)),   phi'''(1) = -lam^4 (mu phi(1) + kappa phi'(1))

(natural conditions of the tip kinetic energy ``1/2 [m_D w_t^2 + 2 M_D w_t w_xt + J_D
w_xt^2]``, the form of Eq 40).  ``phi(0) = phi'(0) = 0`` leaves ``phi = c1 (sin - sinh)
+ c2 (cos - cosh)``.  Condensing the beam on its tip dofs ``u = (phi(1), phi'(1))`` with
the exact dynamic stiffness ``Kb`` (``c, s, C, S`` = ``cos, sin, cosh, sinh`` of ``lam``)::

    Kb = [[lam^3 (cS + sC), -lam^2 sS], [-lam^2 sS, lam (sC - cS)]] / (1 - cC)
    det(Kb - lam^4 T) = lam^4 Delta / (1 - cC),   T = [[mu, kappa], [kappa, eta]]
    Delta = 1 + cC + mu lam (cS - sC) - eta lam^3 (cS + sC) - 2 kappa lam^2 sS
            + (mu eta - kappa^2) lam^4 (1 - cC)

``Delta`` is Eq 39 divided by ``rho^2`` (the printed F matrix has oddly scaled rows but
the right determinant) and reduces to the classical point-mass/rotary-inertia equations.

* :func:`frequency_determinant` is ``Delta / (cosh W)``, ``W = 1 + mu lam + 2|kappa|
  lam^2 + eta lam^3 + |mu eta - kappa^2| lam^4 > 0``: pole-free, in ``[-2, 2]``.  Below
  ``lam = 3`` its pieces are power series (no ``1 - cC ~ lam^4/6`` cancellation).
* Roots are isolated by an exact count (Wittrick-Williams), not by sign changes: the
  eigenvalues below ``lam`` number the clamped-clamped roots below ``lam`` (one in each
  ``(k pi, (k+1) pi)``, ``k >= 1``) plus the negative eigenvalues of ``Kb - lam^4 T``.
  Bisection until each interval holds one eigenvalue, then brentq: close or double roots
  are neither missed nor duplicated.  The count (Sylvester inertia of ``K - omega^2 M``,
  ``K > 0``) holds for any ``T``.
* Shapes: for ``lam >= 3`` ``phi = c1 sin + c2 cos + r e^{lam (xi-1)} + s e^{-lam xi}``
  (``r = tail``, ``s = c1 + r e^{-lam}``), free of ``cosh - sinh`` cancellation; below 3
  the Krylov series ``phi = A K2 + B K3``, ``Km = sum lam^{4k} xi^{4k+m} / (4k+m)!``.
* Integrals are exact antiderivatives: term-wise series below 3, else the Lagrange
  identities ``(lj^4 - lk^4) int phi_j phi_k = [phi_j''' phi_k - phi_j'' phi_k' + phi_j'
  phi_k'' - phi_j phi_k''']_0^1``, ``4 lam^4 int phi^2 = [3 phi phi''' - phi' phi'' + xi
  (lam^4 phi^2 - 2 phi' phi''' + phi''^2)]_0^1``, ``lam^4 int phi = [phi''']_0^1``.  They
  match quadrature to ~1e-14 ``m_l`` (nearly coincident roots lose ``log10(lam/gap)``
  digits).  Eq 40 holds to ~1e-11 for ``mu, eta <~ 1e6`` (worse ~``1e-15 lam
  sqrt(eta)`` beyond), or to ~``eps u^T |T| u`` for heavy near-singular tips.
* Normalised by Eq 40 to the link mass ``m_l``, sign ``phi(L) > 0`` (``phi'(L) > 0`` if
  ``phi(L)`` ~ 0); then ``int EI phi_j'' phi_k'' dx = m_l omega_j^2 delta_jk``.

Non-PSD tip (``M_D^2 > m_D J_D``): Eqs 69-70 take ``J_D1`` from distances projected on
link 2 (``d_l32 = l2 + l3/2 cos q3``) but ``M_D1`` from projections on link 1; with Table 2
data and light hubs ~12 % of configurations have ``M_D1^2 > m_D1 J_D1``.  The problem stays
well posed (``K > 0``: all ``omega^2`` real, exactly one negative, every positive one with
a positive Eq-40 norm), so we warn (:class:`IndefiniteTipInertiaWarning`) and return the
positive-frequency modes.
"""

from __future__ import annotations

import math
import operator
import warnings
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq

from flexctrl.errors import SolverError

__all__ = [
    "ClampedMassModes",
    "IndefiniteTipInertiaWarning",
    "MAX_MODES",
    "clamped_mass_modes",
    "frequency_determinant",
]

Array = NDArray[np.float64]
MAX_MODES = 6
_SERIES_MAX = 3.0  # lam below which power series are used
_NT = 12  # series terms (lam^{4k}/(4k)! < 1e-30 at lam = 3, k = 12)
_KPOW = 4 * np.arange(_NT)
_INV_FACT = np.array([1.0 / math.factorial(i) for i in range(4 * _NT + 8)])


class IndefiniteTipInertiaWarning(RuntimeWarning):
    """The tip inertia matrix ``[[m_D, M_D], [M_D, J_D]]`` is not positive semidefinite."""


def _combos(lam: float) -> tuple[float, float, float, float, float]:
    """``(1 + cC, cS - sC, cS + sC, sS, 1 - cC) / cosh(lam)`` without cancellation."""
    if lam < _SERIES_MAX:
        u, t, sums = -4.0 * lam**4, 1.0, [0.0, 0.0, 0.0, 0.0]
        for k in range(_NT):
            for m in range(4):
                sums[m] += t * _INV_FACT[4 * k + m]
            t *= u
        ch, omc = math.cosh(lam), 1.0 - sums[0]
        if lam < 1.5:  # 1 - cC ~ lam^4/6: sum it without the k = 0 term
            omc, t = 0.0, -u
            for k in range(1, _NT):
                omc += t * _INV_FACT[4 * k]
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


def _delta(lam: float, mu: float, eta: float, kappa: float) -> float:
    return _delta_parts(lam, mu, eta, kappa)[0]


def _count(lam: float, mu: float, eta: float, kappa: float) -> int:
    """Number of eigenvalues (``omega^2 > 0``) strictly below ``lam`` (Wittrick-Williams)."""
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


def _roots(n: int, mu: float, eta: float, kappa: float) -> list[float]:
    """First ``n`` positive roots of ``Delta``, ascending, isolated by counting."""
    if n == 0:
        return []
    hi = (n - 0.5) * math.pi + 0.5  # above the n-th clamped-free root, a bound if T >= 0
    n_hi = _count(hi, mu, eta, kappa)
    for _ in range(1000):  # an indefinite T can raise frequencies
        if n_hi >= n:
            break
        hi += math.pi
        n_hi = _count(hi, mu, eta, kappa)
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
            nm = _count(m, mu, eta, kappa)
            stack += [(m, b, nm, nb), (a, m, na, nm)]
    return sorted(roots)[:n]


#: brentq's relative tolerance on a root ``lam`` (4 eps, the smallest it accepts).
ROOT_RTOL = 8.9e-16


def _polish(a: float, b: float, na: int, mu: float, eta: float, kappa: float) -> float:
    """The single eigenvalue in ``[a, b)``: brentq on the sign change, else count-bisection."""
    fa, fb = _delta(a, mu, eta, kappa), _delta(b, mu, eta, kappa)
    if fa == 0.0:
        return a
    if fa * fb < 0.0:
        return brentq(_delta, a, b, args=(mu, eta, kappa), xtol=1e-300, rtol=ROOT_RTOL)
    while b - a > 4e-16 * b:  # no sign change seen (root within rounding of b)
        m = 0.5 * (a + b)
        if _count(m, mu, eta, kappa) > na:
            b = m
        else:
            a = m
    return 0.5 * (a + b)


# --- one mode: phi(xi) from (lam, c1, c2, tail) ------------------------------------------
def _kfun(lam: float, xi: Array, m: int) -> Array:
    """Krylov series ``K_m(xi) = sum_k lam^{4k} xi^{4k+m} / (4k+m)!``; ``K_{-1} = lam^4 K_3``."""
    if m < 0:
        return lam**4 * _kfun(lam, xi, m + 4)
    return np.power.outer(xi, (_KPOW + m).astype(float)) @ (lam**_KPOW * _INV_FACT[_KPOW + m])


def _ksum(lam: float, m: int, p: int = 0) -> float:
    """``int_0^1 xi^p K_m dxi`` term by term."""
    return float(np.sum(lam**_KPOW * _INV_FACT[_KPOW + m] / (_KPOW + m + p + 1)))


def _krylov(lam: float, c1: float, c2: float) -> tuple[float, float]:
    """``(A, B)`` with ``phi = A K_2 + B K_3``."""
    return -2.0 * lam**2 * c2, -2.0 * lam**3 * c1


def _phi(lam: float, c1: float, c2: float, tail: float, xi: Array, d: int) -> Array:
    """``d``-th ``xi``-derivative of one mode at ``xi``."""
    if lam < _SERIES_MAX:
        a, b = _krylov(lam, c1, c2)
        return a * _kfun(lam, xi, 2 - d) + b * _kfun(lam, xi, 3 - d)
    s = c1 + tail * math.exp(-lam)
    ts, tc = [(c1, c2), (-c2, c1), (-c1, -c2), (c2, -c1)][d]
    return lam**d * (
        ts * np.sin(lam * xi)
        + tc * np.cos(lam * xi)
        + tail * np.exp(lam * (xi - 1.0))
        + (-1) ** d * s * np.exp(-lam * xi)
    )


def _ends(lam: float, c1: float, c2: float, tail: float) -> Array:
    """``[[phi, phi', phi'', phi''']`` at ``xi = 0``, same at ``xi = 1]``."""
    xi = np.array([0.0, 1.0])
    return np.array([_phi(lam, c1, c2, tail, xi, d) for d in range(4)]).T


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


def _raw_mode(lam: float, mu: float, eta: float, kappa: float) -> tuple[float, float, float]:
    """Unnormalised ``(c1, c2, tail)`` satisfying the tip conditions at root ``lam``."""
    ev, vec = np.linalg.eigh(np.array([[mu, kappa], [kappa, eta]]))
    weight = (vec * np.abs(ev)) @ vec.T + np.diag([0.25, 0.25 / max(lam, 1.0) ** 2])
    l4 = lam**4
    if lam < _SERIES_MAX:  # phi'' and phi''' residuals over (A, B), phi = A K2 + B K3
        k0, k1, k2, k3 = (float(_kfun(lam, np.ones(1), m)[0]) for m in range(4))
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
    den = _KPOW[:, None] + _KPOW[None, :]
    tot = 0.0
    for m, cm in zip((2, 3), abj):
        for n, cn in zip((2, 3), abk):
            terms = np.outer(lj**_KPOW * _INV_FACT[_KPOW + m], lk**_KPOW * _INV_FACT[_KPOW + n])
            tot += cm * cn * float(np.sum(terms / (den + m + n + 1)))
    return tot


def _integrals(lam: float, c1: float, c2: float, tail: float) -> tuple[float, float, float]:
    """``int phi``, ``int xi phi`` and ``int phi^2`` over ``0 <= xi <= 1``."""
    if lam < _SERIES_MAX:
        a, b = _krylov(lam, c1, c2)
        return (
            a * _ksum(lam, 2) + b * _ksum(lam, 3),
            a * _ksum(lam, 2, 1) + b * _ksum(lam, 3, 1),
            _pair_series(lam, (a, b), lam, (a, b)),
        )
    (_, _, f2, f3), (g0, g1, g2, g3) = _ends(lam, c1, c2, tail)
    l4 = lam**4
    sq = (3 * g0 * g3 - g1 * g2 + l4 * g0 * g0 - 2 * g1 * g3 + g2 * g2) / (4 * l4)
    return (g3 - f3) / l4, (g3 - g2 + f2) / l4, sq


def _cross(lj: float, mj: tuple, gj: Array, lk: float, mk: tuple, gk: Array) -> float:
    """``int_0^1 phi_j phi_k`` for distinct roots; ``g`` = derivatives 0..3 at ``xi = 1``."""
    if lj < _SERIES_MAX and lk < _SERIES_MAX:
        return _pair_series(lj, _krylov(lj, *mj[:2]), lk, _krylov(lk, *mk[:2]))
    lagrange = gj[3] * gk[0] - gj[2] * gk[1] + gj[1] * gk[2] - gj[0] * gk[3]
    return lagrange / (lj**4 - lk**4)


# --- public API ------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ClampedMassModes:
    """Orthonormal modes of a clamped beam carrying a tip body (see module docstring).

    Parameters
    ----------
    length, rho, EI
        Link length (m), mass per length (kg/m), flexural rigidity (N m^2).
    m_tip, J_tip, M_tip
        Tip mass (kg), rotary inertia about the tip (kg m^2), first-moment coupling (kg m).
    beta
        ``(n,)`` wavenumbers, 1/m, ascending.
    coefficients
        ``(n, 4)`` ``c1..c4`` of ``phi = c1 sin + c2 cos + c3 sinh + c4 cosh`` (of
        ``beta x``), dimensionless, normalised by Eq 40 to the link mass.
        ``c3 = -c1, c4 = -c2``; at large ``beta L`` evaluating this form loses
        ``~beta L / ln 10`` digits, use :meth:`shape` instead.
    tail
        ``(n,)`` ``r`` of the stable form ``phi = c1 sin + c2 cos + r e^{beta (x - L)}
        + s e^{-beta x}`` (``s = c1 + r e^{-beta L}``); ``(c3 + c4) e^{beta L} / 2``
        computed without cancellation.

    Notes
    -----
    ``phi`` is dimensionless, so modal coordinates are in m.  Integral properties
    are computed on first access and are read-only.
    """

    length: float
    rho: float
    EI: float
    m_tip: float
    J_tip: float
    M_tip: float
    beta: Array
    coefficients: Array
    tail: Array

    @property
    def link_mass(self) -> float:
        """Link mass ``rho L``, kg."""
        return self.rho * self.length

    @property
    def n_modes(self) -> int:
        """Number of modes."""
        return int(self.beta.size)

    @property
    def omega(self) -> Array:
        """``(n,)`` natural angular frequencies ``beta^2 sqrt(EI / rho)``, rad/s."""
        return self.beta**2 * math.sqrt(self.EI / self.rho)

    @property
    def frequency_hz(self) -> Array:
        """``(n,)`` natural frequencies, Hz."""
        return self.omega / (2.0 * math.pi)

    def _modes(self) -> list[tuple[float, tuple[float, float, float]]]:
        lam = self.beta * self.length
        return [
            (
                float(lam[j]),
                (
                    float(self.coefficients[j, 0]),
                    float(self.coefficients[j, 1]),
                    float(self.tail[j]),
                ),
            )
            for j in range(self.n_modes)
        ]

    def shape(self, x: ArrayLike, derivative: int = 0) -> Array:
        """Mode shapes or their derivatives.

        Parameters
        ----------
        x
            Positions along the link, m, ``0 <= x <= L``.
        derivative
            0, 1, 2 or 3 for ``phi`` (dimensionless), ``phi'`` (1/m), ``phi''`` (1/m^2),
            ``phi'''`` (1/m^3).

        Returns
        -------
        ndarray, shape ``(n,) + x.shape``
        """
        if derivative not in (0, 1, 2, 3) or isinstance(derivative, bool):
            raise ValueError(f"derivative must be 0, 1, 2 or 3, got {derivative!r}")
        xa = np.asarray(x, dtype=float)
        if not np.all((xa >= 0.0) & (xa <= self.length * (1 + 1e-12))):
            raise ValueError(
                f"x must lie in [0, length={self.length}] m, got values in "
                f"[{np.min(xa, initial=np.inf)}, {np.max(xa, initial=-np.inf)}]"
            )
        xi = np.minimum(xa.ravel() / self.length, 1.0)
        out = np.empty((self.n_modes, xi.size))
        for j, (lam, m) in enumerate(self._modes()):
            out[j] = _phi(lam, *m, xi, derivative)
        return out.reshape((self.n_modes,) + xa.shape) / self.length**derivative

    @cached_property
    def _end_values(self) -> Array:
        vals = [_ends(lam, *m)[1] for lam, m in self._modes()]
        return np.array(vals).reshape(self.n_modes, 4)

    @property
    def tip_deflection(self) -> Array:
        """``(n,)`` ``phi_j(L)``, dimensionless."""
        return self._end_values[:, 0].copy()

    @property
    def tip_slope(self) -> Array:
        """``(n,)`` ``phi_j'(L)``, 1/m."""
        return self._end_values[:, 1] / self.length

    @cached_property
    def _self_integrals(self) -> Array:
        return np.array([_integrals(lam, *m) for lam, m in self._modes()]).reshape(self.n_modes, 3)

    @property
    def v(self) -> Array:
        """``(n,)`` ``int_0^L rho phi_j dx`` (Eq 50), kg."""
        return self.rho * self.length * self._self_integrals[:, 0]

    @property
    def w(self) -> Array:
        """``(n,)`` ``int_0^L rho x phi_j dx`` (Eq 51), kg m."""
        return self.rho * self.length**2 * self._self_integrals[:, 1]

    @cached_property
    def _z(self) -> Array:
        modes, g, n = self._modes(), self._end_values, self.n_modes
        z = np.diag(self._self_integrals[:, 2]) if n else np.zeros((0, 0))
        for j in range(n):
            for k in range(j + 1, n):
                z[j, k] = z[k, j] = _cross(*modes[j], g[j], *modes[k], g[k])
        return self.rho * self.length * z

    @property
    def z(self) -> Array:
        """``(n, n)`` ``int_0^L rho phi_j phi_k dx`` (Eq 52), kg."""
        return self._z.copy()

    @property
    def stiffness(self) -> Array:
        """``(n,)`` ``m_l omega_j^2 = int EI phi_j''^2 dx`` (Eq 53), N/m."""
        return self.link_mass * self.omega**2


def _positive(name: str, value: float, allow_zero: bool) -> float:
    v = float(value)
    ok = math.isfinite(v) and (v >= 0.0 if allow_zero else v > 0.0)
    if not ok:
        rule = "non-negative" if allow_zero else "positive"
        raise ValueError(f"{name} must be a finite {rule} number, got {value!r}")
    return v


def clamped_mass_modes(
    length: float,
    rho: float,
    EI: float,
    n_modes: int,
    m_tip: float = 0.0,
    J_tip: float = 0.0,
    M_tip: float = 0.0,
) -> ClampedMassModes:
    """Natural frequencies and Eq-40-orthonormal modes of a clamped beam with a tip body.

    Parameters
    ----------
    length, rho, EI
        Link length ``L`` (m), mass per length (kg/m), flexural rigidity (N m^2); > 0.
    n_modes
        Number of modes, integer 0..6.
    m_tip, J_tip
        Tip mass ``m_D`` (kg) and rotary inertia about the beam end ``J_D`` (kg m^2); >= 0.
    M_tip
        First-moment coupling ``M_D``, kg m, any sign.  If ``M_tip**2 > m_tip * J_tip``
        an :class:`IndefiniteTipInertiaWarning` is issued and the positive-frequency
        modes are returned (see module docstring).

    Returns
    -------
    ClampedMassModes

    Raises
    ------
    ValueError
        An argument is out of range or not finite.
    TypeError
        ``n_modes`` is not an integer.
    flexctrl.errors.SolverError
        Root isolation failed (not expected for valid input).

    Examples
    --------
    >>> modes = clamped_mass_modes(1.0, 1.0, 1.0, 2)
    >>> modes.beta.round(5).tolist()
    [1.8751, 4.69409]
    >>> modes.frequency_hz.round(4).tolist()
    [0.5596, 3.5069]
    """
    L = _positive("length", length, False)
    rho = _positive("rho", rho, False)
    EI = _positive("EI", EI, False)
    m_d = _positive("m_tip", m_tip, True)
    j_d = _positive("J_tip", J_tip, True)
    m_c = float(M_tip)
    if not math.isfinite(m_c):
        raise ValueError(f"M_tip must be a finite number, got {M_tip!r}")
    if isinstance(n_modes, bool):
        raise TypeError(f"n_modes must be an integer 0..{MAX_MODES}, got {n_modes!r}")
    n = operator.index(n_modes)
    if not 0 <= n <= MAX_MODES:
        raise ValueError(f"n_modes must be an integer 0..{MAX_MODES}, got {n_modes!r}")
    if m_c * m_c - m_d * j_d > 1e-9 * (m_c * m_c + m_d * j_d):
        warnings.warn(
            f"tip inertia [[m_tip, M_tip], [M_tip, J_tip]] = [[{m_d}, {m_c}], [{m_c}, {j_d}]] "
            f"is indefinite (M_tip**2 > m_tip*J_tip): unphysical body; returning the "
            f"positive-frequency modes",
            IndefiniteTipInertiaWarning,
            stacklevel=2,
        )
    ml = rho * L
    mu, eta, kappa = m_d / ml, j_d / (ml * L * L), m_c / (ml * L)
    lams = _roots(n, mu, eta, kappa)
    coef, tails = np.zeros((n, 4)), np.zeros(n)
    for j, lam in enumerate(lams):
        c1, c2, r = _raw_mode(lam, mu, eta, kappa)
        g = _ends(lam, c1, c2, r)[1]
        norm2 = (
            _integrals(lam, c1, c2, r)[2]
            + mu * g[0] ** 2
            + 2 * kappa * g[0] * g[1]
            + eta * g[1] ** 2
        )
        if not norm2 > 0.0:
            raise SolverError(f"non-positive modal mass {norm2} for beta L = {lam}")
        pivot = g[0] if abs(g[0]) > 1e-8 * abs(g[1]) else g[1]
        scale = math.copysign(1.0 / math.sqrt(norm2), pivot)
        c1, c2, r = c1 * scale, c2 * scale, r * scale
        coef[j] = (c1, c2, -c1, -c2)
        tails[j] = r
    beta = np.array(lams, dtype=float) / L
    for a in (beta, coef, tails):
        a.setflags(write=False)
    return ClampedMassModes(L, rho, EI, m_d, j_d, m_c, beta, coef, tails)


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
    f = np.vectorize(
        lambda x: _delta(float(x), float(mu), float(eta), float(kappa)), otypes=[float]
    )
    out = f(la)
    return float(out) if out.ndim == 0 else out
