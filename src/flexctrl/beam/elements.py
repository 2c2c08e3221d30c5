"""Planar Euler-Bernoulli beam elements in closed form (Pan, Scott & Ulsoy 1990, Eqs 29-34).

Units are SI throughout: lengths in m, ``rho`` in kg/m (mass per unit length),
``EI`` in N m^2, ``EA`` in N, axial force ``F`` in N (tension positive).

Bending element
    Hermite cubic, local coordinate ``zeta`` in [0, l] from the element's left node,
    ``xi = zeta / l``.  Element dofs ``(w1, theta1, w2, theta2)`` with
    ``theta = dw/dx`` (slope, not the paper's ``phi_y = -dw/dx``).
Global ordering (``assemble_beam``)
    ``[w_0, theta_0, w_1, theta_1, ..., w_n, theta_n]`` for nodes at ``x_k = k L / n``.
Geometric stiffness (axial shortening, Eqs 16 and 34)
    ``V_a = 1/2 int F(x) w'(x)^2 dx = 1/2 q^T K_g q`` with ``K_g = int F N'^T N' dx``.
    ``F`` is the axial force, *tension positive* (the paper's Eq 17 sign: a link
    pushed from behind has ``F < 0``), so ``K + K_g`` softens in compression.
    Closed form for ``F`` linear along the element (exact for rigid translation);
    for inertial loads with rotation ``F`` is quadratic in ``x`` and
    :func:`geometric_stiffness` integrates any polynomial of degree <= 5 exactly by
    5-point Gauss-Legendre quadrature (``N'^T N'`` is of degree 4).
Axial element
    Linear two-node bar, dofs ``(u1, u2)``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(5)  # exact for degree <= 9


def _check_length(l: float) -> float:
    l = float(l)
    if not (l > 0.0 and np.isfinite(l)):
        raise ValueError(f"element length must be positive and finite, got {l!r}")
    return l


def hermite_shape(zeta: ArrayLike, l: float, derivative: int = 0) -> Array:
    """Hermite cubic shape functions or their ``zeta``-derivatives.

    Parameters
    ----------
    zeta
        Position(s) in the element, m, measured from the left node (0 <= zeta <= l;
        values outside are extrapolated by the same cubic).
    l
        Element length, m.
    derivative
        0 for ``N`` (dimensionless / m for the slope columns), 1 for ``dN/dx``,
        2 for ``d2N/dx2``, 3 for ``d3N/dx3``.

    Returns
    -------
    ndarray, shape ``zeta.shape + (4,)``
        Row(s) such that ``w^(derivative)(zeta) = N @ (w1, theta1, w2, theta2)``.
    """
    l = _check_length(l)
    xi = np.asarray(zeta, dtype=float) / l
    one = np.ones_like(xi)
    if derivative == 0:
        cols = (
            1 - 3 * xi**2 + 2 * xi**3,
            l * (xi - 2 * xi**2 + xi**3),
            3 * xi**2 - 2 * xi**3,
            l * (-(xi**2) + xi**3),
        )
    elif derivative == 1:
        cols = (
            (-6 * xi + 6 * xi**2) / l,
            1 - 4 * xi + 3 * xi**2,
            (6 * xi - 6 * xi**2) / l,
            -2 * xi + 3 * xi**2,
        )
    elif derivative == 2:
        cols = ((-6 + 12 * xi) / l**2, (-4 + 6 * xi) / l, (6 - 12 * xi) / l**2, (-2 + 6 * xi) / l)
    elif derivative == 3:
        cols = (12 / l**3 * one, 6 / l**2 * one, -12 / l**3 * one, 6 / l**2 * one)
    else:
        raise ValueError(f"derivative must be 0, 1, 2 or 3, got {derivative!r}")
    return np.stack(cols, axis=-1)


def beam_mass(rho: float, l: float) -> Array:
    """Consistent mass of a Hermite bending element, ``rho l / 420 [...]`` (kg, kg m, kg m^2).

    Parameters
    ----------
    rho : float
        Mass per length (kg/m).
    l : float
        Element length (m).

    Returns
    -------
    numpy.ndarray
        Shape (4, 4), over ``(w1, w1', w2, w2')``.
    """
    l = _check_length(l)
    return (
        rho
        * l
        / 420.0
        * np.array(
            [
                [156.0, 22 * l, 54.0, -13 * l],
                [22 * l, 4 * l**2, 13 * l, -3 * l**2],
                [54.0, 13 * l, 156.0, -22 * l],
                [-13 * l, -3 * l**2, -22 * l, 4 * l**2],
            ]
        )
    )


def beam_stiffness(EI: float, l: float) -> Array:
    """Bending stiffness ``EI / l^3 [...]`` of a Hermite element (N/m, N, N m).

    Parameters
    ----------
    EI : float
        Bending stiffness (N m^2).
    l : float
        Element length (m).

    Returns
    -------
    numpy.ndarray
        Shape (4, 4), over ``(w1, w1', w2, w2')``.
    """
    l = _check_length(l)
    return (
        EI
        / l**3
        * np.array(
            [
                [12.0, 6 * l, -12.0, 6 * l],
                [6 * l, 4 * l**2, -6 * l, 2 * l**2],
                [-12.0, -6 * l, 12.0, -6 * l],
                [6 * l, 2 * l**2, -6 * l, 4 * l**2],
            ]
        )
    )


def geometric_stiffness_linear(F1: float, F2: float, l: float) -> Array:
    """Geometric stiffness ``int F N'^T N' dzeta`` for ``F = F1 + (F2 - F1) zeta / l``.

    For ``F1 == F2 == P`` this is the classical ``P/(30 l) [36, 3l, ...]``.

    Parameters
    ----------
    F1, F2 : float
        Axial forces at the left and right node (N, tension positive).
    l : float
        Element length (m).

    Returns
    -------
    numpy.ndarray
        Shape (4, 4) (N/m, N, N m).
    """
    l = _check_length(l)
    a = np.array(
        [
            [36.0, 0.0, -36.0, 6 * l],
            [0.0, 6 * l**2, 0.0, -(l**2)],
            [-36.0, 0.0, 36.0, -6 * l],
            [6 * l, -(l**2), -6 * l, 2 * l**2],
        ]
    )
    b = np.array(
        [
            [36.0, 6 * l, -36.0, 0.0],
            [6 * l, 2 * l**2, -6 * l, -(l**2)],
            [-36.0, -6 * l, 36.0, 0.0],
            [0.0, -(l**2), 0.0, 6 * l**2],
        ]
    )
    return (F1 * a + F2 * b) / (60.0 * l)


def geometric_stiffness(force: Callable[[Array], ArrayLike], l: float) -> Array:
    """Geometric stiffness ``int_0^l F(zeta) N'^T N' dzeta`` by 5-point Gauss quadrature.

    Exact when ``F`` is a polynomial of degree <= 5 in ``zeta`` (e.g. the quadratic
    axial force of a rotating link); otherwise a quadrature approximation.

    Parameters
    ----------
    force
        Vectorised ``F(zeta)`` in N (tension positive), ``zeta`` in m from the left node.
    l
        Element length, m.
    """
    l = _check_length(l)
    zeta = 0.5 * l * (_GAUSS_X + 1.0)
    f = np.broadcast_to(np.asarray(force(zeta), dtype=float), zeta.shape)
    d = hermite_shape(zeta, l, derivative=1)
    return 0.5 * l * np.einsum("g,gi,gj->ij", _GAUSS_W * f, d, d)


def axial_mass(rho: float, l: float) -> Array:
    """Consistent mass ``rho l / 6 [[2, 1], [1, 2]]`` of the linear axial element (kg).

    Parameters
    ----------
    rho : float
        Mass per length (kg/m).
    l : float
        Element length (m).

    Returns
    -------
    numpy.ndarray
        Shape (2, 2).
    """
    l = _check_length(l)
    return rho * l / 6.0 * np.array([[2.0, 1.0], [1.0, 2.0]])


def axial_stiffness(EA: float, l: float) -> Array:
    """Axial stiffness ``EA / l [[1, -1], [-1, 1]]`` (N/m).

    Parameters
    ----------
    EA : float
        Axial stiffness (N).
    l : float
        Element length (m).

    Returns
    -------
    numpy.ndarray
        Shape (2, 2).
    """
    l = _check_length(l)
    return EA / l * np.array([[1.0, -1.0], [-1.0, 1.0]])


def mass_integrals(rho: float, l: float, x0: float = 0.0) -> tuple[Array, Array]:
    """Mass-weighted shape-function integrals for floating-frame coupling terms.

    ``S0 @ q_e`` is the first moment of transverse deflection, ``S1 @ q_e`` its moment about
    the origin.

    Parameters
    ----------
    rho : float
        Mass per length (kg/m).
    l : float
        Element length (m).
    x0 : float
        Position of the element's left node in the link frame (m).

    Returns
    -------
    tuple of numpy.ndarray
        ``S0 = int rho N dzeta`` (kg, kg m) and ``S1 = int rho (x0 + zeta) N dzeta``
        (kg m, kg m^2), each of shape (4,).
    """
    l = _check_length(l)
    s0 = rho * np.array([l / 2, l**2 / 12, l / 2, -(l**2) / 12])
    s_zeta = rho * np.array([3 * l**2 / 20, l**3 / 30, 7 * l**2 / 20, -(l**3) / 20])
    return s0, x0 * s0 + s_zeta


def locate(x: float, n_elements: int, length: float) -> tuple[int, float]:
    """Element index ``j`` (0-based) and local ``zeta`` of position ``x`` on a uniform mesh.

    A point on an interior node is assigned to the element on its right (the last
    node to the last element).  A tolerance of 1e-12 length outside the beam is clamped.

    Parameters
    ----------
    x : float
        Position along the beam (m).
    n_elements : int
        Number of equal elements.
    length : float
        Beam length (m).

    Returns
    -------
    tuple
        ``(j, zeta)``, ``zeta`` in m from the element's left node.

    Raises
    ------
    ValueError
        When ``x`` lies outside ``[0, length]``.
    """
    le = length / n_elements
    tol = 1e-12 * length
    if not (-tol <= x <= length + tol):
        raise ValueError(f"position x = {x!r} m lies outside the beam [0, {length}] m")
    x = min(max(x, 0.0), length)
    j = min(int(x // le), n_elements - 1)
    return j, x - j * le


def interpolation_row(x: float, n_elements: int, length: float, derivative: int = 0) -> Array:
    """Global row ``r`` with ``w^(derivative)(x) = r @ q`` on a uniform mesh (see module doc).

    Parameters
    ----------
    x : float
        Position along the beam (m).
    n_elements : int
        Number of equal elements.
    length : float
        Beam length (m).
    derivative : int
        Order of the ``x``-derivative, 0 to 3.

    Returns
    -------
    numpy.ndarray
        Shape ``(2 (n_elements + 1),)``.
    """
    j, zeta = locate(x, n_elements, length)
    row = np.zeros(2 * (n_elements + 1))
    row[2 * j : 2 * j + 4] = hermite_shape(zeta, length / n_elements, derivative)
    return row


@dataclass(frozen=True)
class BeamMatrices:
    """Global matrices of a uniform beam (see :func:`assemble_beam`).

    Attributes
    ----------
    M, K : numpy.ndarray
        Bending mass and stiffness over the nodal ``(w, w')``.
    node_x : numpy.ndarray
        Node positions (m).
    element_length : float
        Element length (m).
    S0, S1 : numpy.ndarray
        ``int rho N dx`` (kg, kg m) and ``int rho x N dx`` (kg m, kg m^2).
    M_axial, K_axial : numpy.ndarray or None
        Axial mass (kg) and stiffness (N/m), when an ``EA`` was given.
    """

    M: Array
    K: Array
    node_x: Array
    element_length: float
    S0: Array
    S1: Array
    M_axial: Array | None = None
    K_axial: Array | None = None


def _assemble(blocks: list[Array], stride: int, size: int) -> Array:
    out = np.zeros((size, size))
    k = blocks[0].shape[0]
    for j, b in enumerate(blocks):
        out[stride * j : stride * j + k, stride * j : stride * j + k] += b
    return out


def assemble_beam(
    n_elements: int, length: float, rho: float, EI: float, EA: float | None = None
) -> BeamMatrices:
    """Assemble bending (and optionally axial) matrices of a free uniform beam.

    Parameters
    ----------
    n_elements
        Number of equal elements (>= 1).
    length
        Beam length L, m.
    rho, EI, EA
        Mass per length (kg/m), bending stiffness (N m^2), axial stiffness (N).

    Returns
    -------
    BeamMatrices
        ``M``, ``K`` of size ``2(n+1)``; ``S0``, ``S1`` = global ``int rho N dx`` and
        ``int rho x N dx`` (x from node 0); ``M_axial``, ``K_axial`` of size ``n+1``
        when ``EA`` is given.  No boundary conditions are applied.
    """
    n = int(n_elements)
    if n < 1:
        raise ValueError(f"n_elements must be >= 1, got {n_elements!r}")
    le = _check_length(length) / n
    size = 2 * (n + 1)
    M = _assemble([beam_mass(rho, le)] * n, 2, size)
    K = _assemble([beam_stiffness(EI, le)] * n, 2, size)
    S0 = np.zeros(size)
    S1 = np.zeros(size)
    for j in range(n):
        s0, s1 = mass_integrals(rho, le, x0=j * le)
        S0[2 * j : 2 * j + 4] += s0
        S1[2 * j : 2 * j + 4] += s1
    Ma = Ka = None
    if EA is not None:
        Ma = _assemble([axial_mass(rho, le)] * n, 1, n + 1)
        Ka = _assemble([axial_stiffness(EA, le)] * n, 1, n + 1)
    return BeamMatrices(
        M=M,
        K=K,
        node_x=np.linspace(0.0, float(length), n + 1),
        element_length=le,
        S0=S0,
        S1=S1,
        M_axial=Ma,
        K_axial=Ka,
    )


def assemble_geometric_stiffness(
    n_elements: int, length: float, force: ArrayLike | Callable[[Array], ArrayLike]
) -> Array:
    """Global geometric stiffness ``int_0^L F(x) N'^T N' dx`` of a uniform mesh.

    Parameters
    ----------
    n_elements : int
        Number of equal elements.
    length : float
        Beam length (m).
    force
        Either nodal axial forces, shape ``(n+1,)`` (N, tension positive), taken
        piecewise linear (closed form, exact for linear ``F``), or a vectorised
        callable ``F(x)`` of the link coordinate ``x`` (exact for polynomial ``F``
        of degree <= 5 via :func:`geometric_stiffness`).
    """
    n = int(n_elements)
    le = _check_length(length) / n
    if callable(force):
        blocks = [geometric_stiffness(_shifted(force, j * le), le) for j in range(n)]
    else:
        fn = np.asarray(force, dtype=float)
        if fn.shape != (n + 1,):
            raise ValueError(f"nodal forces must have shape ({n + 1},), got {fn.shape}")
        blocks = [geometric_stiffness_linear(fn[j], fn[j + 1], le) for j in range(n)]
    return _assemble(blocks, 2, 2 * (n + 1))


def _shifted(force: Callable[[Array], ArrayLike], x0: float) -> Callable[[Array], ArrayLike]:
    """``z -> force(x0 + z)``: an axial force along the link seen from an element's left node."""
    return lambda z: force(x0 + z)
