"""Modal facts of a linear system and of the structure: frequencies and damping.

:func:`modal_summary` gives the natural frequencies and damping ratios of a linear
system's eigenvalues; :func:`locked_frequencies` the undamped frequencies of the structure
with the joints clamped (``K_ff`` against ``M_ff``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import control
import numpy as np

from flexctrl.dynamics.model import Model
from flexctrl.dynamics.natural_frequencies import locked_spectrum
from flexctrl.errors import keyword_checked
from flexctrl.linear.model_facts import stiffness_matrix
from flexctrl.linear.operating_point import OperatingPoint


@dataclass(frozen=True, eq=False)
class ModalSummary:
    """Natural frequencies and damping of a linear system's eigenvalues.

    One entry per complex-conjugate pair (the member with positive imaginary part)
    and per real eigenvalue, sorted by natural frequency.

    Attributes
    ----------
    eigenvalues : ndarray (complex)
        Continuous-time eigenvalues (for a discrete system: ``log(z) / dt``), 1/s.
    frequency_hz : ndarray
        Undamped natural frequencies ``|s| / 2 pi``, Hz.
    damping : ndarray
        Damping ratios ``-Re(s) / |s|`` (NaN for a zero eigenvalue).
    """

    eigenvalues: np.ndarray
    frequency_hz: np.ndarray
    damping: np.ndarray

    @property
    def oscillatory(self) -> np.ndarray:
        """Mask of the complex pairs (vibration modes)."""
        return np.abs(self.eigenvalues.imag) > 0

    def rows(self) -> list[dict[str, float]]:
        """One dict per entry: ``frequency_hz``, ``damping``, ``real``, ``imag``."""
        return [
            {
                "frequency_hz": float(f),
                "damping": float(z),
                "real": float(s.real),
                "imag": float(s.imag),
            }
            for s, f, z in zip(self.eigenvalues, self.frequency_hz, self.damping)
        ]


@keyword_checked
def modal_summary(sys: control.StateSpace, tol: float = 1e-9) -> ModalSummary:
    """Frequencies (Hz) and damping ratios of the eigenvalues of ``sys`` (continuous or discrete).

    Parameters
    ----------
    sys : control.StateSpace
        Continuous, or discrete (its eigenvalues mapped by ``s = ln(z) / dt``).
    tol : float
        Relative size below which an imaginary part counts as zero; of each complex pair
        only the member with a positive imaginary part is kept.

    Returns
    -------
    ModalSummary
        ``eigenvalues`` (1/s), ``frequency_hz`` (Hz) and ``damping`` (ratio; negative for
        an unstable mode, NaN at zero), sorted by frequency.
    """
    eig = np.linalg.eigvals(np.asarray(sys.A, dtype=float))
    if control.isdtime(sys, strict=True):
        with np.errstate(divide="ignore"):
            eig = np.log(eig.astype(complex)) / sys.dt
    scale = max(1.0, float(np.max(np.abs(eig), initial=0.0)))
    keep = [s for s in eig if s.imag > tol * scale or abs(s.imag) <= tol * scale]
    s = np.array([complex(v.real, 0.0) if abs(v.imag) <= tol * scale else v for v in keep])
    mag = np.abs(s)
    with np.errstate(invalid="ignore", divide="ignore"):
        zeta = np.where(mag > 0, -s.real / np.where(mag > 0, mag, 1.0), np.nan)
    order = np.argsort(mag, kind="stable")
    return ModalSummary(s[order], mag[order] / (2 * math.pi), zeta[order])


@keyword_checked
def locked_frequencies(
    model: Model, op: OperatingPoint | None = None, *, include_gravity: bool = False
) -> np.ndarray:
    """Undamped natural frequencies (Hz, ascending) of the structure with the joints clamped.

    Generalised eigenvalues of ``K_ff`` against ``M_ff`` at the configuration of
    ``op`` (default: zero joint angles and deflections).  ``include_gravity`` adds
    the gravitational stiffness ``d g_f / d q_f`` (the linearisation's elastic block).
    Both matrices are symmetrised (:func:`flexctrl.dynamics.natural_frequencies.locked_spectrum`
    computes the spectrum).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The model of the structure.
    op : OperatingPoint, optional
        Where the mass and stiffness matrices are taken.
    include_gravity : bool
        Add the gravitational stiffness of the elastic coordinates.

    Returns
    -------
    numpy.ndarray
        Frequencies, Hz, one per elastic coordinate.
    """
    n, N = model.n_u, model.n_q
    if N == n:
        return np.zeros(0)
    q0 = np.zeros(N) if op is None else np.asarray(op.q, dtype=float)
    M = model.mass_matrix(q0)
    K = stiffness_matrix(model, q0)
    if include_gravity:
        qs = ca.SX.sym("q", N)
        dg = ca.Function("dg", [qs], [ca.jacobian(model.functions["g"](qs), qs)])
        G = np.array(dg(q0), dtype=float)
        K = K + 0.5 * (G + G.T)
    return locked_spectrum(0.5 * (M + M.T), 0.5 * (K + K.T), n) / (2 * math.pi)
