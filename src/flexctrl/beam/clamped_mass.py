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

from flexctrl.beam.clamped_mass_roots import frequency_roots
from flexctrl.beam.clamped_mass_shapes import (
    cross_integral,
    end_values,
    mode_derivative,
    mode_integrals,
    raw_mode,
)
from flexctrl.errors import SolverError

__all__ = [
    "ClampedMassModes",
    "IndefiniteTipInertiaWarning",
    "MAX_MODES",
    "clamped_mass_modes",
]

Array = NDArray[np.float64]
MAX_MODES = 6


class IndefiniteTipInertiaWarning(RuntimeWarning):
    """The tip inertia matrix ``[[m_D, M_D], [M_D, J_D]]`` is not positive semidefinite."""


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
            out[j] = mode_derivative(lam, *m, xi, derivative)
        return out.reshape((self.n_modes,) + xa.shape) / self.length**derivative

    @cached_property
    def _end_values(self) -> Array:
        vals = [end_values(lam, *m)[1] for lam, m in self._modes()]
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
        return np.array([mode_integrals(lam, *m) for lam, m in self._modes()]).reshape(
            self.n_modes, 3
        )

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
                z[j, k] = z[k, j] = cross_integral(*modes[j], g[j], *modes[k], g[k])
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
    L, rho, EI, m_d, j_d, m_c, n = _checked(length, rho, EI, n_modes, m_tip, J_tip, M_tip)
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
    lams = frequency_roots(n, mu, eta, kappa)
    coef, tails = np.zeros((n, 4)), np.zeros(n)
    for j, lam in enumerate(lams):
        c1, c2, r = _normalised_mode(lam, mu, eta, kappa)
        coef[j] = (c1, c2, -c1, -c2)
        tails[j] = r
    beta = np.array(lams, dtype=float) / L
    for a in (beta, coef, tails):
        a.setflags(write=False)
    return ClampedMassModes(L, rho, EI, m_d, j_d, m_c, beta, coef, tails)


def _checked(
    length: float,
    rho: float,
    EI: float,
    n_modes: int,
    m_tip: float,
    J_tip: float,
    M_tip: float,
) -> tuple[float, float, float, float, float, float, int]:
    """The arguments of :func:`clamped_mass_modes` as floats and an int, refused if out of range."""
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
    return L, rho, EI, m_d, j_d, m_c, n


def _normalised_mode(lam: float, mu: float, eta: float, kappa: float) -> tuple[float, float, float]:
    """``(c1, c2, tail)`` of the mode at root ``lam``, normalised by Eq 40 to the link mass.

    The sign makes ``phi(L) > 0`` (``phi'(L) > 0`` when ``phi(L)`` is about zero).
    """
    c1, c2, r = raw_mode(lam, mu, eta, kappa)
    g = end_values(lam, c1, c2, r)[1]
    norm2 = (
        mode_integrals(lam, c1, c2, r)[2]
        + mu * g[0] ** 2
        + 2 * kappa * g[0] * g[1]
        + eta * g[1] ** 2
    )
    if not norm2 > 0.0:
        raise SolverError(f"non-positive modal mass {norm2} for beta L = {lam}")
    pivot = g[0] if abs(g[0]) > 1e-8 * abs(g[1]) else g[1]
    scale = math.copysign(1.0 / math.sqrt(norm2), pivot)
    return c1 * scale, c2 * scale, r * scale
