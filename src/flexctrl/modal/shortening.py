"""Modal integrals of a bent link's axial shortening (foreshortening), for the assumed-modes model.

A link bent by ``w(x) = sum_j phi_j(x) q_j`` whose neutral axis keeps its length has its
points drawn towards the root by ``s(x) = 1/2 int_0^x w'^2 = sum_p N_p(x) sigma_p(q)`` with
one term per mode pair ``p = (j, k)``, ``j <= k`` (:func:`mode_pairs`),
``sigma_p = q_j q_k`` and

    ``N_p(x) = -c_p int_0^x phi_j' phi_k'``,  ``c_p = 1/2`` for ``j = k``, else 1

(the sign makes ``N_p`` the axial displacement, like ``phi_j`` the transverse one).  The
assumed-modes kinematics then needs, besides Eqs 50-52, the integrals over the link

    ``tip[p] = N_p(L)`` (1/m), ``v[p] = int rho N_p`` (kg/m), ``w[p] = int rho x N_p`` (kg),
    ``y[l, p] = int rho phi_l N_p`` (kg/m), ``z[p, p'] = int rho N_p N_p'`` (kg/m^2),

all by Gauss-Legendre quadrature (``GAUSS_POINTS`` nodes on the link; ``N_p`` at each node by
the same rule on ``[0, x]``).  See ``docs/explanation/assumed-modes.md`` section 10 for the
derivation.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

#: Gauss-Legendre nodes on the link and on each partial length (as the lookup's shape-rate
#: integrals).
GAUSS_POINTS = 24
#: Field names, in the order the kinematics and the lookup tables carry them.
SHORTENING_FIELDS = ("sh_tip", "sh_v", "sh_w", "sh_y", "sh_z")


def mode_pairs(n_modes: int) -> list[tuple[int, int]]:
    """Mode pairs ``(j, k)``, ``j <= k``, row by row: the order of ``sigma_p = q_j q_k``.

    Parameters
    ----------
    n_modes : int
        Modes of the link.

    Returns
    -------
    list of tuple of int
        ``n_modes (n_modes + 1) / 2`` pairs.
    """
    return [(j, k) for j in range(n_modes) for k in range(j, n_modes)]


def gauss_nodes(
    length: float, rho: float, points: int = GAUSS_POINTS
) -> tuple[np.ndarray, np.ndarray]:
    """Nodes (m) and mass weights (kg) of the Gauss-Legendre rule on ``[0, length]``.

    Parameters
    ----------
    length : float
        Link length (m).
    rho : float
        Mass per length (kg/m).
    points : int
        Points of the rule.

    Returns
    -------
    tuple of numpy.ndarray
        Nodes (m) and weights (kg).
    """
    t, wt = np.polynomial.legendre.leggauss(points)
    return 0.5 * length * (t + 1.0), 0.5 * length * wt * rho


def axial_shapes(
    slope: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    n_modes: int,
    points: int = GAUSS_POINTS,
) -> np.ndarray:
    """``N_p(x)`` (1/m), shape ``(n_pairs, len(x))``.

    Parameters
    ----------
    slope : callable
        ``slope(xs)`` returns ``phi'`` (n_modes, len(xs)), 1/m.
    x : numpy.ndarray
        Positions along the link (m).
    n_modes : int
        Modes of the link.
    points : int
        Gauss points per integral ``int_0^x``.

    Returns
    -------
    numpy.ndarray
        ``N_p(x)`` (1/m).
    """
    t, wt = np.polynomial.legendre.leggauss(points)
    x = np.asarray(x, dtype=float)
    sub = 0.5 * x[:, None] * (t[None, :] + 1.0)  # (len(x), points) nodes on [0, x]
    d = np.asarray(slope(sub.ravel()), dtype=float).reshape(n_modes, x.size, points)
    S = np.einsum("jgt,kgt,t,g->jkg", d, d, wt, 0.5 * x)  # int_0^x phi_j' phi_k'
    return np.array([-(0.5 if j == k else 1.0) * S[j, k] for j, k in mode_pairs(n_modes)]).reshape(
        -1, x.size
    )


def shortening_integrals(
    shape: Callable[[np.ndarray, int], np.ndarray], length: float, rho: float, n_modes: int
) -> dict[str, np.ndarray]:
    """The integrals of the module docstring for ``shape(x, derivative)`` -> (n_modes, len(x)).

    Parameters
    ----------
    shape : callable
        ``shape(x, derivative)`` of the modes, ``x`` in m.
    length : float
        Link length (m).
    rho : float
        Mass per length (kg/m).
    n_modes : int
        Modes of the link.

    Returns
    -------
    dict of str to numpy.ndarray
        ``{"sh_tip", "sh_v", "sh_w", "sh_y", "sh_z"}`` with shapes ``(P,)``, ``(P,)``,
        ``(P,)``, ``(n_modes, P)``, ``(P, P)``, ``P = n_modes (n_modes + 1) / 2``.

    Examples
    --------
    A single straight-line slope ``phi' = 1/L`` (``phi = x/L``): ``N = -x / (2 L^2)``.

    >>> line = lambda x, d: (np.ones_like(x) if d else x)[None, :] / 2.0
    >>> out = shortening_integrals(line, 2.0, 3.0, 1)
    >>> [round(float(out[k].ravel()[0]), 12) for k in ("sh_tip", "sh_v", "sh_w", "sh_z")]
    [-0.25, -0.75, -1.0, 0.125]
    """
    x, weights = gauss_nodes(length, rho)
    slope = lambda xs: shape(xs, 1)  # noqa: E731
    N = axial_shapes(slope, x, n_modes)
    tip = axial_shapes(slope, np.array([length]), n_modes)[:, 0]
    phi = np.asarray(shape(x, 0), dtype=float).reshape(n_modes, x.size)
    return {
        "sh_tip": tip,
        "sh_v": N @ weights,
        "sh_w": N @ (weights * x),
        "sh_y": np.einsum("lg,pg,g->lp", phi, N, weights),
        "sh_z": np.einsum("pg,rg,g->pr", N, N, weights),
    }


def link_shortening(modes) -> dict[str, np.ndarray]:
    """:func:`shortening_integrals` of a :class:`~flexctrl.beam.clamped_mass.ClampedMassModes`.

    Parameters
    ----------
    modes : ClampedMassModes
        The link's modes (or any object with ``shape``, ``length``, ``rho``, ``n_modes``).

    Returns
    -------
    dict of str to numpy.ndarray
        As :func:`shortening_integrals`.
    """
    return shortening_integrals(modes.shape, modes.length, modes.rho, modes.n_modes)
