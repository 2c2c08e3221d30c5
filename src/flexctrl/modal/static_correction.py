"""Clamped-mass modes and a static-correction shape for a tip moment (truncation augmentation).

A link's clamped-mass modes (:mod:`flexctrl.beam.clamped_mass`) treat everything outboard as
one rigid body fixed to the link's tip, with the tip inertia ``J_D`` of the whole outboard arm
about the next joint.  When that joint is free (or torque driven) the outboard arm does not
resist the tip's rotation: the link's tip sees the joint torque's reaction, a concentrated
moment, and almost no rotary inertia.  The clamped-mass modes, whose tip slope is held back by
``J_D`` (Eq 40 bounds ``|phi_j'(L)|`` by ``sqrt(m_l / J_D)``), represent the static bending
under a tip moment ``w = M x^2 / (2 EI)`` only through a slowly converging series, so a
model with a few of them misses the link's quasi-static answer to the torque
(``docs/explanation/assumed-modes.md`` section 13).

The correction: the static shape of the cantilever under a unit tip moment, ``psi(x) = x^2``
(up to scale), made mass-orthogonal to the ``N`` modes in Eq 40's inner product (link and tip
body) and normalised to the link mass::

    psi_c = psi - sum_j phi_j <psi, phi_j> / m_l,   phi_c = sqrt(m_l / <psi_c, psi_c>) psi_c,
    <f, g> = int rho f g + m_D f(L) g(L) + M_D (f(L) g'(L) + f'(L) g(L)) + J_D f'(L) g'(L).

Because the ``phi_j`` are exact eigenfunctions of that inner product and of the bending energy
``int EI f'' g''``, ``phi_c`` is also stiffness-orthogonal to them, so the augmented set keeps
the assumed-modes model's diagonal ``K = diag(m_l omega^2)``, with ``omega_c^2 = int EI
phi_c''^2 / m_l`` (the Rayleigh quotient), and the ``N`` clamped-mass modes and their
frequencies are unchanged.  Integrals of the correction are by Gauss-Legendre quadrature
(``QUAD_POINTS``; the modes' own integrals stay the closed forms).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike

from flexctrl.beam.clamped_mass import ClampedMassModes
from flexctrl.beam.elements import assemble_beam, hermite_shape, locate
from flexctrl.modal.boundary import boundary_values
from flexctrl.spec.arm import ArmSpec

#: Composite Gauss-Legendre rule for the corrections' integrals: ``QUAD_PANELS`` equal panels
#: (aligned with the elements of :func:`pinned_root_shapes`, so piecewise cubics integrate
#: exactly) of ``QUAD_POINTS`` nodes each.
QUAD_PANELS, QUAD_POINTS = 48, 6


def _poly(x: np.ndarray, length: float, derivative: int) -> np.ndarray:
    """The tip-moment shape ``(x / L)^2`` (dimensionless) and its derivatives."""
    xi = x / length
    return [xi**2, 2 * xi / length, 2 / length**2 + 0 * xi, 0 * xi][derivative]


def tip_moment_shape(length: float):
    """``psi(x, d)``: the cantilever's static shape under a tip moment, ``(x / L)^2``, one row.

    Parameters
    ----------
    length : float
        Link length ``L`` (m).

    Returns
    -------
    callable
        ``psi(x, d)``: the ``d``-th derivative at ``x`` (m), shape (1, len(x)).
    """
    return lambda x, d: _poly(np.asarray(x, dtype=float), length, d)[None, :]


@dataclass(frozen=True)
class CorrectedModes:
    """``base``'s modes followed by the correction shapes ``extra`` (module docstring).

    ``extra(x, d)`` returns the ``d``-th derivatives of the raw shapes, ``(k, len(x))``; they
    are made mass-orthogonal to ``base`` and, among themselves, mass- and stiffness-orthogonal
    (the Ritz eigenproblem in their residual subspace), each normalised to the link mass.
    Has the fields of :class:`~flexctrl.beam.clamped_mass.ClampedMassModes` that the
    assumed-modes model reads (``omega``, ``tip_deflection``, ``tip_slope``, ``v``, ``w``,
    ``z``, ``shape``, ``length``, ``rho``, ``n_modes``), in the same units.

    Parameters
    ----------
    base : ClampedMassModes
        The link's clamped-mass modes.
    extra : callable
        ``extra(x, d)``: the raw correction shapes' ``d``-th derivatives at ``x`` (m).
    """

    base: ClampedMassModes
    extra: object = None

    @property
    def length(self) -> float:
        """Link length, m."""
        return self.base.length

    @property
    def rho(self) -> float:
        """Mass per length, kg/m."""
        return self.base.rho

    @property
    def EI(self) -> float:
        """Flexural rigidity, N m^2."""
        return self.base.EI

    @property
    def link_mass(self) -> float:
        """Link mass, kg."""
        return self.base.link_mass

    def _raw(self, x, d):
        return (self.extra or tip_moment_shape(self.length))(x, d)

    @property
    def n_modes(self) -> int:
        """Clamped-mass modes plus the corrections."""
        return self.base.n_modes + self._raw(np.array([self.length]), 0).shape[0]

    @cached_property
    def _nodes(self) -> tuple[np.ndarray, np.ndarray]:
        t, wt = np.polynomial.legendre.leggauss(QUAD_POINTS)
        h = self.length / QUAD_PANELS
        left = h * np.arange(QUAD_PANELS)[:, None]
        return (left + 0.5 * h * (t + 1.0)).ravel(), np.tile(0.5 * h * wt, QUAD_PANELS)

    @cached_property
    def _coefficients(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(C, A, omega)``: corrections ``phi_c = A^T (psi - C phi)`` (rows) and frequencies."""
        b, L = self.base, self.length
        x, wt = self._nodes
        end = np.array([L])
        T = np.array([[b.m_tip, b.M_tip], [b.M_tip, b.J_tip]])
        phi, psi = b.shape(x), self._raw(x, 0)
        phi_tip = np.vstack([b.tip_deflection, b.tip_slope])  # (2, N)
        psi_tip = np.vstack([self._raw(end, 0)[:, 0], self._raw(end, 1)[:, 0]])  # (2, k)
        C = (
            (b.rho * psi * wt) @ phi.T + psi_tip.T @ T @ phi_tip
        ) / b.link_mass  # (k, N): <psi_i, phi_j> / m_l
        res, res_tip = psi - C @ phi, psi_tip - phi_tip @ C.T
        mass = b.rho * (res * wt) @ res.T + res_tip.T @ T @ res_tip
        curv = self._raw(x, 2) - C @ b.shape(x, 2)
        stiff = self.EI * (curv * wt) @ curv.T
        lam, V = scipy.linalg.eigh(stiff, mass)
        return C, V * np.sqrt(b.link_mass), np.sqrt(lam)

    def _correction(self, x: np.ndarray, derivative: int) -> np.ndarray:
        C, A, _ = self._coefficients
        return A.T @ (self._raw(x, derivative) - C @ self.base.shape(x, derivative))

    def shape(self, x, derivative: int = 0) -> np.ndarray:
        """Shapes (``n_modes`` rows, the corrections last) or their derivatives at ``x`` (m)."""
        xa = np.asarray(x, dtype=float)
        base = self.base.shape(xa, derivative).reshape(self.base.n_modes, -1)
        return np.vstack([base, self._correction(xa.ravel(), derivative)]).reshape(
            (self.n_modes,) + xa.shape
        )

    @cached_property
    def _tip(self) -> np.ndarray:
        L = np.array([self.length])
        return np.vstack([self._correction(L, 0)[:, 0], self._correction(L, 1)[:, 0]])

    @property
    def tip_deflection(self) -> np.ndarray:
        """``phi_j(L)`` of every shape, dimensionless."""
        return np.append(self.base.tip_deflection, self._tip[0])

    @property
    def tip_slope(self) -> np.ndarray:
        """``phi_j'(L)`` of every shape, 1/m."""
        return np.append(self.base.tip_slope, self._tip[1])

    @property
    def v(self) -> np.ndarray:
        """``int rho phi_j dx``, kg."""
        x, wt = self._nodes
        return np.append(self.base.v, self.rho * self._correction(x, 0) @ wt)

    @property
    def w(self) -> np.ndarray:
        """``int rho x phi_j dx``, kg m."""
        x, wt = self._nodes
        return np.append(self.base.w, self.rho * self._correction(x, 0) @ (wt * x))

    @property
    def z(self) -> np.ndarray:
        """``int rho phi_j phi_k dx``, kg."""
        x, wt = self._nodes
        n = self.base.n_modes
        phi = self.shape(x)
        z = self.rho * (phi * wt) @ phi.T
        z[:n, :n] = self.base.z
        return z

    @property
    def omega(self) -> np.ndarray:
        """rad/s; the corrections' from their Ritz eigenproblem."""
        return np.append(self.base.omega, self._coefficients[2])

    @property
    def frequency_hz(self) -> np.ndarray:
        """Frequencies, Hz."""
        return self.omega / (2 * np.pi)

    @property
    def stiffness(self) -> np.ndarray:
        """``m_l omega_j^2``, N/m."""
        return self.link_mass * self.omega**2


def pinned_root_shapes(
    arm: ArmSpec,
    q: Sequence[float] | np.ndarray | None,
    link: int,
    count: int,
    n_elements: int = QUAD_PANELS,
) -> PinnedRootShapes:
    """``psi(x, d)`` of ``count`` rows: the link's modes, root pinned, less their root rotation.

    The root is *pinned* on its hub's rotor.  The link (0-based ``link``) as a Hermite-cubic beam of
    ``n_elements`` elements with ``w(0) = 0``, the rotor inertia of its hub on the root slope and
    the clamped-mass tip body (:func:`flexctrl.modal.boundary.boundary_values`) at the tip; its
    flexible modes ``W_k`` (the zero-frequency rotation skipped) give the clamped-admissible shapes
    ``W_k(x) - W_k'(0) x``: in the link's root frame, the motion of the link when the hub turns
    against it.

    Parameters
    ----------
    arm : ArmSpec
        The arm described.
    q : sequence of float or None
        Joint angles (rad) that set the tip body; ``None``: the arm's configuration.
    link : int
        The link, 0-based.
    count : int
        Number of shapes.
    n_elements : int
        Elements of the beam model.

    Returns
    -------
    PinnedRootShapes
        The shapes and the pinned modes' frequencies (rad/s).
    """
    spec = arm.links[link]
    L = spec.length
    mats = assemble_beam(n_elements, L, spec.mass_per_length, spec.EI)
    M, K = mats.M.copy(), mats.K.copy()
    bv = boundary_values(arm, np.asarray(arm.configuration_or_default(q), dtype=float), link)
    M[1, 1] += arm.joints[link].hub_inertia
    M[-2:, -2:] += np.array([[float(bv.m), float(bv.M)], [float(bv.M), float(bv.J)]])
    keep = np.arange(1, M.shape[0])  # w(0) = 0
    lam, V = scipy.linalg.eigh(K[np.ix_(keep, keep)], M[np.ix_(keep, keep)])
    modes = np.zeros((M.shape[0], count))
    modes[keep] = V[:, 1 : count + 1]  # skip the rotation about the pin
    return PinnedRootShapes(modes, L, n_elements, np.sqrt(np.abs(lam[1 : count + 1])))


@dataclass(frozen=True)
class PinnedRootShapes:
    """The shapes of :func:`pinned_root_shapes`, callable as ``psi(x, d)`` (rows, one per shape).

    Attributes
    ----------
    modes : ndarray
        Nodal values of the pinned-root modes ``W_k`` (dofs x count).
    length : float
        Link length, m.
    n_elements : int
        Hermite elements of the mesh.
    frequencies : ndarray
        The modes' natural frequencies, rad/s.
    """

    modes: np.ndarray
    length: float
    n_elements: int
    frequencies: np.ndarray

    def __call__(self, x: ArrayLike, d: int) -> np.ndarray:
        """The ``d``-th derivative (0..2) of the shapes at ``x`` (m), ``(count, len(x))``."""
        L, n_elements, modes = self.length, self.n_elements, self.modes
        le = L / n_elements
        xs = np.asarray(x, dtype=float).ravel()
        out = np.empty((modes.shape[1], xs.size))
        for i, xi in enumerate(xs):
            j, zeta = locate(min(xi, L), n_elements, L)
            out[:, i] = hermite_shape(zeta, le, d) @ modes[2 * j : 2 * j + 4]
        rot = modes[1]  # W_k'(0)
        return (
            out
            - rot[:, None]
            * (xs if d == 0 else (np.ones_like(xs) if d == 1 else np.zeros_like(xs)))[None, :]
        )
