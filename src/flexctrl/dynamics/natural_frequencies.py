"""Undamped natural frequencies of a structure (``K v = lambda M v``), free or joints clamped."""

from __future__ import annotations

import warnings

import numpy as np
import scipy.linalg


def natural_frequencies(K: np.ndarray, M: np.ndarray) -> np.ndarray:
    """Undamped natural frequencies (rad/s, ascending) of ``M qdd + K q = 0``.

    The square roots of the eigenvalues of ``K v = lambda M v``.  ``M`` symmetric positive
    definite; only the lower triangles are read (``scipy.linalg.eigh``), so pass
    ``0.5 (A + A^T)`` for a matrix that is symmetric only to rounding when both triangles
    should count.  Negative eigenvalues are clipped to 0, with a RuntimeWarning when they
    exceed rounding (``1e-9`` of the largest).

    Parameters
    ----------
    K : ndarray
        Stiffness (N x N), N/m or N m/rad.
    M : ndarray
        Mass (N x N), kg or kg m^2.

    Returns
    -------
    ndarray
        ``N`` frequencies, rad/s.
    """
    lam = scipy.linalg.eigh(K, M, eigvals_only=True)
    if np.any(lam < -1e-9 * max(1.0, float(np.max(np.abs(lam), initial=0.0)))):
        warnings.warn(
            f"the structure has negative stiffness eigenvalues {lam[lam < 0]}; clipped to 0",
            RuntimeWarning,
            stacklevel=3,
        )
    return np.sqrt(np.clip(lam, 0.0, None))


def locked_spectrum(M: np.ndarray, K: np.ndarray, n_joints: int) -> np.ndarray:
    """Natural frequencies (rad/s, ascending) with the joints clamped: ``K_ff`` against ``M_ff``.

    ``M`` and ``K`` are the whole model's (N x N); the elastic block is the one after the
    ``n_joints`` joint coordinates.  The one copy of this spectrum: the model's
    ``info["locked_frequencies_rad_s"]`` and :func:`flexctrl.linear.locked_frequencies`.

    Parameters
    ----------
    M, K : ndarray
        Mass and stiffness of the whole model (N x N).
    n_joints : int
        Joint coordinates first in ``q``.

    Returns
    -------
    ndarray
        ``N - n_joints`` frequencies, rad/s (empty for a rigid model).
    """
    if M.shape[0] == n_joints:
        return np.zeros(0)
    flex = slice(n_joints, None)
    return natural_frequencies(K[flex, flex], M[flex, flex])
