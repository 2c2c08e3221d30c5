"""Finite-element integrals of one clamped link in its floating frame (Pan et al. 1990, Eqs 29-34).

A link of length ``L`` is cut into ``N`` equal elements: Hermite cubics for the
transverse deflection ``w(x) = N_w(x) q_w`` and linear elements for the axial
displacement ``u(x) = N_u(x) q_u`` (:mod:`flexctrl.beam.elements`).  The base node
is clamped in the link frame (see :mod:`flexctrl.dynamics.fem.fem_arm` for why), so the
dofs are those of nodes ``1..N``::

    q_w = (w_1, theta_1, ..., w_N, theta_N)   (m, rad; theta = dw/dx)
    q_u = (u_1, ..., u_N)                     (m)

Integrals (``rho`` kg/m, ``x`` from the link base), all exact (Gauss-Legendre with
5 points per element integrates polynomials up to degree 9):

``M_w = int rho N_w^T N_w``, ``M_u = int rho N_u^T N_u``     consistent masses
``K_w = int EI N_w''^T N_w''``, ``K_u = int EA N_u'^T N_u'``  stiffnesses
``s0w = int rho N_w``, ``s1w = int rho x N_w``                first moments of w
``s0u = int rho N_u``, ``s1u = int rho x N_u``                first moments of u
``C_wu = int rho N_w^T N_u``                                  bending-axial cross mass
``G_e = int_e N_w'^T N_w'`` (4 x 4, per element)              ``int_e w'^2 = q_e^T G_e q_e``

``G_e`` gives the element mean of ``w'^2`` used in the membrane strain of the
axial-shortening option (:mod:`flexctrl.dynamics.fem.fem_arm`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from flexctrl.beam.elements import hermite_shape

Array = NDArray[np.float64]

_GX, _GW = np.polynomial.legendre.leggauss(5)


@dataclass(frozen=True)
class LinkMatrices:
    """Clamped-base FE integrals of one link (see module docstring); node 0 removed."""

    n_elements: int
    length: float
    M_w: Array
    K_w: Array
    M_u: Array
    K_u: Array
    s0w: Array
    s1w: Array
    s0u: Array
    s1u: Array
    C_wu: Array
    G_e: Array

    @property
    def n_w(self) -> int:
        """Bending dofs 2N."""
        return 2 * self.n_elements

    @property
    def n_u(self) -> int:
        """Axial dofs N."""
        return self.n_elements


def _linear_shape(zeta: Array, l: float, derivative: int = 0) -> Array:
    xi = zeta / l
    if derivative == 0:
        return np.stack([1.0 - xi, xi], axis=-1)
    return np.stack([-np.ones_like(xi) / l, np.ones_like(xi) / l], axis=-1)


def link_matrices(length: float, rho: float, EI: float, EA: float, n_elements: int) -> LinkMatrices:
    """Assemble the integrals of a uniform link with ``n_elements`` equal elements.

    Parameters
    ----------
    length, rho, EI, EA
        m, kg/m, N m^2, N (all > 0).
    n_elements
        >= 1.
    """
    n = int(n_elements)
    if n < 1:
        raise ValueError(f"n_elements must be >= 1, got {n_elements!r}")
    L = float(length)
    le = L / n
    nw, nu = 2 * (n + 1), n + 1
    M_w, K_w = np.zeros((nw, nw)), np.zeros((nw, nw))
    M_u, K_u = np.zeros((nu, nu)), np.zeros((nu, nu))
    C = np.zeros((nw, nu))
    s0w, s1w, s0u, s1u = np.zeros(nw), np.zeros(nw), np.zeros(nu), np.zeros(nu)
    zeta = 0.5 * le * (_GX + 1.0)
    wq = 0.5 * le * _GW
    H0, H1, H2 = (hermite_shape(zeta, le, d) for d in (0, 1, 2))
    A0, A1 = _linear_shape(zeta, le, 0), _linear_shape(zeta, le, 1)
    for j in range(n):
        x = j * le + zeta
        bw, bu = slice(2 * j, 2 * j + 4), slice(j, j + 2)
        M_w[bw, bw] += rho * np.einsum("g,gi,gk->ik", wq, H0, H0)
        K_w[bw, bw] += EI * np.einsum("g,gi,gk->ik", wq, H2, H2)
        M_u[bu, bu] += rho * np.einsum("g,gi,gk->ik", wq, A0, A0)
        K_u[bu, bu] += EA * np.einsum("g,gi,gk->ik", wq, A1, A1)
        C[bw, bu] += rho * np.einsum("g,gi,gk->ik", wq, H0, A0)
        s0w[bw] += rho * wq @ H0
        s1w[bw] += rho * (wq * x) @ H0
        s0u[bu] += rho * wq @ A0
        s1u[bu] += rho * (wq * x) @ A0
    w, u = slice(2, None), slice(1, None)  # clamp node 0
    return LinkMatrices(
        n_elements=n,
        length=L,
        M_w=M_w[w, w],
        K_w=K_w[w, w],
        M_u=M_u[u, u],
        K_u=K_u[u, u],
        s0w=s0w[w],
        s1w=s1w[w],
        s0u=s0u[u],
        s1u=s1u[u],
        C_wu=C[w, u],
        G_e=np.einsum("g,gi,gk->ik", wq, H1, H1),
    )
