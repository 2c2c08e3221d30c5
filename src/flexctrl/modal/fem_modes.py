"""Per-link clamped-mass frequencies by Hermite finite elements (``modes --fidelity fem:N``).

The check on :func:`flexctrl.modal.arm_modes.link_modes`: the same clamped-mass
beam (Subedi et al. 2021, Eqs 20-40) -- link ``i`` clamped at its joint, the
outboard hubs, links and payload acting as one rigid body on its tip -- but
discretised with ``N`` equal Hermite bending elements
(:mod:`flexctrl.beam.elements`) instead of solved in closed form.  The tip body
enters as the kinetic energy ``1/2 [m_D w_t^2 + 2 M_D w_t w_xt + J_D w_xt^2]``
(the quadratic form behind Eqs 33-36), i.e. the matrix ``[[m_D, M_D], [M_D, J_D]]``
added to the mass matrix at the last node's ``(w, theta)`` dofs; boundary values
come from :func:`flexctrl.modal.boundary.boundary_values`.

Consistent mass with Hermite cubics is a Rayleigh-Ritz method on nested meshes
when ``N`` doubles, so the frequencies fall monotonically onto the closed-form
ones; the eigenvalue error decreases as ``h^4`` (``h = L/N``).

Non-PSD tip inertia (``M_D^2 > m_D J_D``, see :mod:`flexctrl.beam.clamped_mass`):
the mass matrix is then indefinite; the problem is solved as ``M v = mu K v``
(``K`` is positive definite after clamping), the one negative ``mu`` is dropped
with an :class:`~flexctrl.beam.clamped_mass.IndefiniteTipInertiaWarning`, and the
positive ones give ``omega^2 = 1/mu``.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import scipy.linalg

from flexctrl.beam.clamped_mass import IndefiniteTipInertiaWarning
from flexctrl.beam.elements import assemble_beam
from flexctrl.errors import SpecError
from flexctrl.modal.boundary import boundary_values
from flexctrl.spec.arm import ArmSpec

__all__ = ["clamped_mass_matrices", "link_frequencies_fem"]


def clamped_mass_matrices(
    length: float,
    rho: float,
    EI: float,
    n_elements: int,
    m_tip: float = 0.0,
    J_tip: float = 0.0,
    M_tip: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Mass and stiffness of a clamped Hermite beam with a rigid tip body.

    Parameters
    ----------
    length, rho, EI
        Link length (m), mass per length (kg/m), flexural rigidity (N m^2).
    n_elements
        Equal elements (>= 1).
    m_tip, J_tip, M_tip
        Tip mass (kg), rotary inertia about the beam end (kg m^2), first moment (kg m).

    Returns
    -------
    (M, K)
        Size ``2 N``: dofs ``(w_1, theta_1, ..., w_N, theta_N)`` of the free nodes
        (node 0 clamped), units kg / kg m / kg m^2 and N/m / N / N m.
    """
    mats = assemble_beam(n_elements, length, rho, EI)
    M, K = mats.M[2:, 2:].copy(), mats.K[2:, 2:].copy()
    M[-2:, -2:] += np.array([[m_tip, M_tip], [M_tip, J_tip]])
    return M, K


def link_frequencies_fem(
    arm: ArmSpec, q: np.ndarray, link: int, n_modes: int, n_elements: int
) -> np.ndarray:
    """Lowest natural frequencies (Hz, ascending) of one clamped-mass link by finite elements.

    Parameters
    ----------
    arm
        The arm; its payload and ``boundary_inertia`` set the tip body.
    q
        Joint angles (rad), shape ``(n,)``.
    link
        Link index, 0-based.
    n_modes
        Frequencies wanted (>= 0; at most ``2 * n_elements``, the dofs of the mesh).
    n_elements
        Hermite elements on the link (>= 1).

    Returns
    -------
    numpy.ndarray
        Shape ``(n_modes,)``, Hz.

    Raises
    ------
    SpecError
        For a link index, mode count or element count out of range.

    Examples
    --------
    >>> from flexctrl.spec.arm import load_arm
    >>> arm = load_arm("models/subedi3link.toml").with_payload(0.0)
    >>> link_frequencies_fem(arm, [0.0, 0.0, 0.0], 2, 2, 16).round(2)
    array([14.17, 88.82])
    """
    _check_counts(arm, link, n_modes, n_elements)
    spec = arm.links[link]
    bv = boundary_values(arm, np.asarray(q, dtype=float), link)
    m_D, J_D, M_D = float(bv.m), float(bv.J), float(bv.M)
    M, K = clamped_mass_matrices(
        spec.length, spec.mass_per_length, spec.EI, int(n_elements), m_D, J_D, M_D
    )
    if n_modes == 0:
        return np.zeros(0)
    if M_D * M_D <= m_D * J_D:
        lam = scipy.linalg.eigh(K, M, eigvals_only=True, subset_by_index=[0, n_modes - 1])
        return np.sqrt(np.clip(lam, 0.0, None)) / (2.0 * math.pi)
    warnings.warn(
        f"link {link + 1}: tip inertia [[m_D, M_D], [M_D, J_D]] = [[{m_D:.4g}, {M_D:.4g}], "
        f"[{M_D:.4g}, {J_D:.4g}]] is not positive semidefinite; the negative eigenvalue is dropped",
        IndefiniteTipInertiaWarning,
        stacklevel=2,
    )
    mu = scipy.linalg.eigh(M, K, eigvals_only=True)
    mu = np.sort(mu[mu > 0.0])[::-1]
    if mu.size < n_modes:
        raise SpecError(
            f"only {mu.size} positive frequencies exist for link {link + 1} with an indefinite tip "
            f"inertia; asked for {n_modes}",
            key="n_modes",
        )
    return np.sqrt(1.0 / mu[:n_modes]) / (2.0 * math.pi)


def _check_counts(arm: ArmSpec, link: int, n_modes: int, n_elements: int) -> None:
    """Refuse a link index, element count or mode count out of range (:class:`SpecError`)."""
    if not 0 <= link < arm.n_links:
        raise SpecError(
            f"link {link!r} is out of range; allowed: 0 to {arm.n_links - 1} (0-based)", key="link"
        )
    if (
        isinstance(n_elements, bool)
        or not isinstance(n_elements, (int, np.integer))
        or n_elements < 1
    ):
        raise SpecError(
            f"value {n_elements!r} is not allowed; allowed: an integer >= 1 (elements per link)",
            key="n_elements",
        )
    if (
        isinstance(n_modes, bool)
        or not isinstance(n_modes, (int, np.integer))
        or not 0 <= n_modes <= 2 * n_elements
    ):
        raise SpecError(
            f"value {n_modes!r} is out of range; allowed: 0 to {2 * n_elements} "
            f"(a mesh of {n_elements} elements has {2 * n_elements} bending dofs)",
            key="n_modes",
        )
