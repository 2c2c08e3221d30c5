"""Beam theory that knows nothing of robots: clamped-mass modes and beam finite elements."""

from flexctrl.beam.clamped_mass import (
    MAX_MODES,
    ClampedMassModes,
    IndefiniteTipInertiaWarning,
    clamped_mass_modes,
)
from flexctrl.beam.clamped_mass_roots import frequency_determinant

__all__ = [
    "MAX_MODES",
    "ClampedMassModes",
    "IndefiniteTipInertiaWarning",
    "clamped_mass_modes",
    "frequency_determinant",
]
