"""Clamped-mass modes of every link of an arm at one configuration and payload."""

from __future__ import annotations

import numpy as np

from flexctrl.beam.clamped_mass import ClampedMassModes, clamped_mass_modes
from flexctrl.modal.boundary import boundary_values
from flexctrl.spec.arm import ArmSpec


def link_modes(
    arm: ArmSpec, q: np.ndarray, link: int, n_modes: int | None = None, convention: str | None = None
) -> ClampedMassModes:
    """Modes of ``link`` (0-based) at joint angles ``q`` (rad).

    Parameters
    ----------
    arm
        Arm description; its payload and ``boundary_inertia`` are used.
    q
        Joint angles (rad), shape (n,).
    link
        Link index, 0-based.
    n_modes
        Modes to compute (default: the link's ``n_modes``).
    convention
        ``"exact"`` or ``"paper"`` boundary inertia (default: the arm's).
    """
    spec = arm.links[link]
    bv = boundary_values(arm, np.asarray(q, dtype=float), link, convention)
    return clamped_mass_modes(
        spec.length,
        spec.mass_per_length,
        spec.EI,
        spec.n_modes if n_modes is None else n_modes,
        m_tip=float(bv.m),
        J_tip=float(bv.J),
        M_tip=float(bv.M),
    )


def arm_modes(arm: ArmSpec, q: np.ndarray, n_modes: int | None = None, convention: str | None = None) -> list[ClampedMassModes]:
    """Modes of every link, ordered from link 1 outward (see :func:`link_modes`)."""
    return [link_modes(arm, q, i, n_modes, convention) for i in range(arm.n_links)]
