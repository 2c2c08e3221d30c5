"""Damping of an arm's coupled modes: a target damping ratio on every elastic mode at one pose.

Subedi et al.'s Eq 68 (and the other per-link forms of :data:`flexctrl.spec.damping.DAMPING_FORMS`)
damp each link's clamped-mass modes; the arm's coupled modes, which mix the links' modes with
the joints' motion, then see other ratios (on the shipped arm, 0.01 per link gives 0.05-0.36).
Classical modal damping puts the ratio an engineer asks for on the coupled modes themselves:
with ``Phi`` the modes of ``K phi = omega^2 M phi`` normalised to ``Phi' M Phi = I``,

    D = M Phi diag(2 zeta omega_k) Phi' M,

so that ``Phi' D Phi = diag(2 zeta omega_k)`` and every mode of ``M q'' + D q' + K q = 0`` is
``s^2 + 2 zeta omega_k s + omega_k^2``.  Rigid-body modes (``omega_k = 0``: the free joints)
are left undamped; joint friction adds to ``D`` on the joint coordinates.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sl

#: Eigenvalues ``omega^2`` below this fraction of the largest are rigid-body modes.
RIGID_FRACTION = 1e-9


def coupled_modal_damping(mass: np.ndarray, stiffness: np.ndarray, zeta: float) -> np.ndarray:
    """``D`` giving the damping ratio ``zeta`` to every elastic mode of ``(M, K)``.

    Parameters
    ----------
    mass : (N, N) array
        Mass matrix at the pose (kg, kg m, kg m^2), symmetric positive definite.
    stiffness : (N, N) array
        Stiffness matrix (N/m, N m), symmetric positive semidefinite (zero rows for free
        joints).
    zeta : float
        Damping ratio, >= 0.

    Returns
    -------
    numpy.ndarray
        (N, N) symmetric damping matrix (kg/s, kg m/s, kg m^2/s).

    Examples
    --------
    >>> import numpy as np
    >>> M, K = np.array([[2.0, 0.5], [0.5, 1.0]]), np.diag([0.0, 100.0])
    >>> D = coupled_modal_damping(M, K, 0.05)
    >>> s = np.linalg.eigvals(np.block([[np.zeros((2, 2)), np.eye(2)],
    ...                                 [-np.linalg.solve(M, K), -np.linalg.solve(M, D)]]))
    >>> oscillatory = s[np.abs(s.imag) > 0]
    >>> np.allclose(-oscillatory.real / np.abs(oscillatory), 0.05)
    True
    """
    M = 0.5 * (np.asarray(mass, dtype=float) + np.asarray(mass, dtype=float).T)
    K = 0.5 * (np.asarray(stiffness, dtype=float) + np.asarray(stiffness, dtype=float).T)
    omega2, phi = sl.eigh(K, M)
    elastic = omega2 > RIGID_FRACTION * max(float(np.max(omega2, initial=0.0)), 0.0)
    rates = np.where(elastic, 2.0 * float(zeta) * np.sqrt(np.clip(omega2, 0.0, None)), 0.0)
    shapes = M @ phi
    D = shapes @ np.diag(rates) @ shapes.T
    return 0.5 * (D + D.T)
