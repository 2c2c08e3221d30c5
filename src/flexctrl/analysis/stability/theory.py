"""The largest stable step of an integrator for a set of eigenvalues, predicted by theory.

Theory: :func:`theoretical_step_limit`
    The largest ``h`` with ``|R(lambda_i h)| <= 1`` for every eigenvalue of ``A``
    (the first exit of each ray ``lambda_i h`` from the stability region):

    * ``rk4``: ``R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24``.  On the imaginary axis
      (undamped modes) the exit is at ``|z| = 2 sqrt 2 = 2.828``; on the negative
      real axis at ``2.785`` (:data:`RK4_REAL_AXIS_LIMIT`).  2.785 is often quoted
      "on the imaginary axis": it is the real-axis value, 1.5 % below the
      imaginary-axis one that governs an undamped arm, and the bound the
      integrators use (:data:`flexctrl.sim.rk4.RK4_STABILITY_LIMIT`: safe for
      every undamped mode).  We report the exact ray intersection as
      ``h_theory`` and record the gap (``docs/explanation/numerical-stability.md``).
    * ``euler``: ``R(z) = 1 + z``: ``h = 0`` if any mode is undamped, else
      ``min_i 2 zeta_i / omega_i`` (``= -2 Re(lambda) / |lambda|^2``).
    * ``newmark``: ``inf`` for ``2 alpha >= delta >= 1/2`` (the default average
      acceleration rule is the trapezoidal rule, ``R(z) = (1 + z/2)/(1 - z/2)``,
      ``|R| <= 1`` on the whole left half-plane); otherwise Hughes' critical
      ``omega h`` with ``omega = |lambda|``, ``zeta = -Re(lambda)/|lambda|``
      (:func:`flexctrl.sim.newmark_model.newmark_critical_step`).

    With ``omega_osc = max |Im lambda|`` (the fastest oscillation; ``omega_max``
    if none oscillates), eigenvalues with ``|lambda| <= 1e-8 omega_osc`` count as
    zero (rigid-body motion: ``|R(0)| = 1`` limits nothing), those with
    ``|Re lambda| <= 1e-8 omega_osc`` as undamped (the accuracy of computed
    eigenvalues: on the undamped fem:8 arm the real parts scatter by 5e-11 with
    ``omega_osc = 1.3e5``), those with ``Re lambda > 1e-8 omega_osc`` as
    physically growing (an unstable equilibrium): no integrator should damp
    them, so they are left out of the theory and of the probe and counted
    (``n_growing``).  The scale is the fastest oscillation, not ``omega_max``:
    stiffness-proportional damping of finite-element models gives overdamped
    real eigenvalues up to 5.7e7 rad/s (fem:8, zeta = 0.02), and 1e-8 of that
    would count the joints' friction-damped modes (``Re lambda = -7e-3``) as
    undamped.

The measurement this theory is compared with: :mod:`flexctrl.analysis.stability.probe`.

Units: SI throughout (s, rad/s).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from flexctrl.errors import SpecError
from flexctrl.sim.newmark_model import newmark_critical_step

#: Amplification polynomials ``R(z) = sum c_k z^k`` of the explicit methods (coefficients c_0, c_1,
#: ...).
EXPLICIT_POLYNOMIALS: dict[str, tuple[float, ...]] = {
    "euler": (1.0, 1.0),
    "rk4": (1.0, 1.0, 1.0 / 2.0, 1.0 / 6.0, 1.0 / 24.0),
}
#: Methods with a stability theory here.
THEORY_METHODS = ("rk4", "euler", "newmark")
#: Eigenvalues within this fraction of the fastest oscillation of zero (or of the imaginary axis)
#: are treated as such.
EIGENVALUE_TOL = 1e-8


def amplification_factor(
    method: str, z: complex | np.ndarray, *, alpha: float = 0.25, delta: float = 0.5
) -> np.ndarray:
    """``R(z)``, ``z = lambda h``, of ``"euler"``, ``"rk4"`` or ``"newmark"`` (trapezoidal
    parameters only).

    Raises
    ------
    SpecError
        For another method, or Newmark with parameters other than alpha = 1/4, delta = 1/2
        (whose amplification is a 2x2 matrix per mode, not a scalar function of z).
    """
    z = np.asarray(z, dtype=complex)
    if method in EXPLICIT_POLYNOMIALS:
        return np.polynomial.polynomial.polyval(z, EXPLICIT_POLYNOMIALS[method])
    if method == "newmark" and alpha == 0.25 and delta == 0.5:
        return (1 + z / 2) / (1 - z / 2)
    raise SpecError(
        f"method {method!r} (alpha = {alpha}, delta = {delta}) has no scalar amplification factor "
        "here; allowed: 'euler', 'rk4', 'newmark' with alpha = 0.25, delta = 0.5",
        key="method",
    )


def ray_limit(coefficients: Sequence[float], direction: complex) -> float:
    """Where the ray ``s d`` (``s > 0``, ``|d| = 1``) first leaves ``|R(z)| <= 1`` for a polynomial
    ``R``.

    ``|R(s d)|^2 - 1`` is a real polynomial in ``s``; its coefficients are formed
    exactly and those below the rounding of their own terms set to zero (on the
    imaginary axis RK4's low-order terms cancel exactly).

    Parameters
    ----------
    coefficients
        ``c_0, c_1, ...`` of ``R(z) = sum c_k z^k`` (``c_0 = 1``).
    direction
        The ray's direction (normalised here).

    Returns
    -------
    float
        The smallest ``s > 0`` beyond which ``|R| > 1``; 0 if ``|R| > 1`` right
        away; ``inf`` if never.

    Examples
    --------
    >>> round(ray_limit(EXPLICIT_POLYNOMIALS["rk4"], 1j) ** 2, 12)
    8.0
    >>> ray_limit(EXPLICIT_POLYNOMIALS["euler"], 1j)
    0.0
    """
    d = complex(direction) / abs(complex(direction))
    a = np.asarray(coefficients, dtype=float) * d ** np.arange(len(coefficients))
    p = np.convolve(a, np.conj(a)).real
    scale = np.convolve(np.abs(a), np.abs(a))
    p[np.abs(p) <= 64 * np.finfo(float).eps * scale] = 0.0
    p[0] -= 1.0
    if abs(p[0]) <= 64 * np.finfo(float).eps:
        p[0] = 0.0
    nonzero = np.flatnonzero(p)
    if nonzero.size == 0:
        return math.inf
    low = nonzero[0]
    if p[low] > 0:
        return 0.0
    q = p[low:]
    roots = np.roots(q[::-1])
    positive = sorted(r.real for r in roots if r.real > 0 and abs(r.imag) <= 1e-9 * abs(r))
    for s in positive:
        if np.polynomial.polynomial.polyval(s * (1 + 1e-7), p) > 0:
            return float(s)
    return math.inf


def _rk4_real_axis_limit() -> float:
    return ray_limit(EXPLICIT_POLYNOMIALS["rk4"], -1.0)


#: Classical RK4's stability limit on the negative real axis, 2.7853 (computed).
RK4_REAL_AXIS_LIMIT = _rk4_real_axis_limit()
#: Classical RK4's stability limit on the imaginary axis, 2 sqrt(2) = 2.8284.
RK4_IMAGINARY_AXIS_LIMIT = 2.0 * math.sqrt(2.0)


@dataclass(frozen=True)
class TheoryLimit:
    """The theoretical largest stable step of a method for a set of eigenvalues.

    Attributes
    ----------
    method : str
    h : float
        Largest stable step (s); 0 when no step is stable, ``inf`` when every step is.
    omega_max : float
        Largest ``|lambda|`` (rad/s).
    limiting_eigenvalue : complex or None
        The eigenvalue whose ray leaves the stability region first (rad/s); None when ``h`` is inf.
    n_zero, n_undamped, n_damped, n_growing : int
        Eigenvalues treated as zero, on the imaginary axis, in the open left
        half-plane, in the right half-plane (left out).
    """

    method: str
    h: float
    omega_max: float
    limiting_eigenvalue: complex | None
    n_zero: int
    n_undamped: int
    n_damped: int
    n_growing: int

    @property
    def omega_h(self) -> float:
        """``omega_max * h`` (dimensionless)."""
        return self.omega_max * self.h if self.h > 0 else 0.0


def classify_eigenvalues(
    eigenvalues: np.ndarray, tol: float = EIGENVALUE_TOL
) -> tuple[np.ndarray, np.ndarray, float]:
    """Split eigenvalues (rad/s) into kinds; returns ``(kind, snapped, omega_max)``.

    ``kind`` is ``"zero"``, ``"undamped"``, ``"damped"`` or ``"growing"`` per
    eigenvalue (thresholds ``tol * omega_osc``, see module docstring) and
    ``snapped`` the eigenvalues with undamped ones put exactly on the imaginary axis.
    """
    lam = np.asarray(eigenvalues, dtype=complex).ravel()
    omega_max = float(np.max(np.abs(lam), initial=0.0))
    omega_osc = float(np.max(np.abs(lam.imag), initial=0.0)) or omega_max
    eps = tol * omega_osc
    kind = np.full(lam.shape, "damped", dtype=object)
    snapped = lam.copy()
    undamped = np.abs(lam.real) <= eps
    snapped[undamped] = 1j * lam.imag[undamped]
    kind[undamped] = "undamped"
    kind[lam.real > eps] = "growing"
    kind[np.abs(lam) <= eps] = "zero"
    return kind, snapped, omega_max


def theoretical_step_limit(
    eigenvalues: np.ndarray,
    method: str,
    *,
    alpha: float = 0.25,
    delta: float = 0.5,
    tol: float = EIGENVALUE_TOL,
) -> TheoryLimit:
    """Largest ``h`` (s) with ``|R(lambda_i h)| <= 1`` for every eigenvalue ``lambda_i`` (rad/s).

    Parameters
    ----------
    eigenvalues
        Of the linearisation ``A = df/dx`` (rad/s).
    method
        ``"rk4"``, ``"euler"`` or ``"newmark"``.
    alpha, delta
        Newmark parameters.
    tol
        Relative eigenvalue tolerance (module docstring).

    Raises
    ------
    SpecError
        For another method.

    Examples
    --------
    >>> lam = [10j, -10j]
    >>> round(theoretical_step_limit(lam, "rk4").h * 10, 12) == round(2 * 2 ** 0.5, 12)
    True
    >>> theoretical_step_limit(lam, "euler").h, theoretical_step_limit(lam, "newmark").h
    (0.0, inf)
    """

    if method not in THEORY_METHODS:
        raise SpecError(
            f"method {method!r} has no stability theory here; allowed: "
            f"{', '.join(map(repr, THEORY_METHODS))}",
            key="method",
        )
    kind, snapped, omega_max = classify_eigenvalues(eigenvalues, tol)
    best, limiting = math.inf, None
    for lam, k in zip(snapped, kind):
        if k in ("zero", "growing"):
            continue
        size = float(abs(lam))
        if method in EXPLICIT_POLYNOMIALS:
            h = ray_limit(EXPLICIT_POLYNOMIALS[method], complex(lam)) / size
        else:
            zeta = min(max(-float(lam.real) / size, 0.0), 1.0)
            h = newmark_critical_step(alpha, delta, zeta) / size
        if h < best:
            best, limiting = h, complex(lam)
    counts = {name: int(np.sum(kind == name)) for name in ("zero", "undamped", "damped", "growing")}
    return TheoryLimit(
        method,
        best,
        omega_max,
        limiting,
        counts["zero"],
        counts["undamped"],
        counts["damped"],
        counts["growing"],
    )


__all__ = [
    "EIGENVALUE_TOL",
    "EXPLICIT_POLYNOMIALS",
    "RK4_IMAGINARY_AXIS_LIMIT",
    "RK4_REAL_AXIS_LIMIT",
    "THEORY_METHODS",
    "TheoryLimit",
    "amplification_factor",
    "classify_eigenvalues",
    "ray_limit",
    "theoretical_step_limit",
]
