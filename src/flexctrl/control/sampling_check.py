"""Is a design model's sampled form fragile?  Undamped elastic modes and modes near aliasing.

A controller that samples every ``T`` seconds sees an elastic mode ``s = -sigma +- j w``
through the pair of sampled eigenvalues ``exp(s T)``, whose angle is ``+- w T`` with
``w = 2 pi f`` (``f`` the mode's damped frequency, Hz).  When ``f`` is a whole multiple
``k`` of half the sample rate ``fs / 2 = 1 / (2 T)``, the pair meets on the real axis (the
positive half for even ``k``, the negative half for odd ``k``): the two sampled modes
coincide and the pair loses controllability from the held torque (the PBH test's smallest
value falls towards zero).  Near that point the Riccati gains that still control the pair
grow without bound, and the design holds only on a plant sampled exactly as modelled.  The
rule, with the relative distance

    d = min over k >= 1 of |f - k fs/2| / (fs/2),

flags a mode with ``d < tolerance`` (3 % by default: the sampled pair then sits within
``0.03 pi`` rad of the real axis, since ``|sin(w T)| = sin(pi d)``).  The undamped case is
flagged on its own: with a damping ratio of (numerically) zero the design model's modes sit
on the unit circle, the design relies on damping that a real arm has in an unknown amount,
and every near-aliased mode lies exactly on the stability boundary.

:func:`sampling_diagnosis` applies both rules to a model at an operating point;
:func:`flexctrl.control.design` calls it for every controller it builds and issues a
:class:`~flexctrl.errors.DesignWarning`, and the closed loop's divergence message repeats
the diagnosis (:attr:`flexctrl.control.controller.Controller.design_diagnosis`).
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from flexctrl.linear import Linearizer, OperatingPoint, modal_summary

#: Relative distance ``d`` (of ``fs/2``) below which a mode counts as near aliasing.
ALIAS_TOLERANCE = 0.03

#: Damping ratio below which an elastic mode counts as undamped (numerical zero: a real
#: structure's damping is two orders of magnitude above it).
UNDAMPED_RATIO = 1e-4


def alias_distance(frequency_hz, sample_time: float) -> tuple[np.ndarray, np.ndarray]:
    """Relative distance of each frequency from the nearest multiple ``k >= 1`` of ``fs/2``.

    Parameters
    ----------
    frequency_hz : array_like
        Mode frequencies, Hz.
    sample_time : float
        The controller's sample time ``T``, s (``fs/2 = 1 / (2 T)``).

    Returns
    -------
    d : ndarray
        ``|f - k fs/2| / (fs/2)`` (dimensionless, 0 to 1).
    k : ndarray of int
        The multiple ``k >= 1`` that is nearest.
    """
    half = 0.5 / float(sample_time)
    f = np.atleast_1d(np.asarray(frequency_hz, dtype=float))
    k = np.maximum(1, np.rint(f / half)).astype(int)
    return np.abs(f - k * half) / half, k


@dataclass(frozen=True, eq=False)
class SamplingDiagnosis:
    """The elastic modes of a design model against its controller's sample time.

    Attributes
    ----------
    frequency_hz : ndarray
        Damped frequencies ``|Im s| / 2 pi`` of the elastic modes, Hz, ascending.
    damping : ndarray
        Their damping ratios.
    sample_time : float
        The controller's sample time, s.
    distance : ndarray
        Each mode's relative distance ``d`` from the nearest multiple ``k`` of ``fs/2``.
    multiple : ndarray of int
        That ``k``.
    tolerance : float
        The ``d`` below which a mode is flagged.
    """

    frequency_hz: np.ndarray
    damping: np.ndarray
    sample_time: float
    distance: np.ndarray
    multiple: np.ndarray
    tolerance: float = ALIAS_TOLERANCE

    @property
    def undamped(self) -> np.ndarray:
        """Mask of the modes whose damping ratio is below :data:`UNDAMPED_RATIO`."""
        return self.damping < UNDAMPED_RATIO

    @property
    def near_alias(self) -> np.ndarray:
        """Mask of the modes within ``tolerance`` of a multiple of ``fs/2``."""
        return self.distance < self.tolerance

    @property
    def flagged(self) -> bool:
        """Whether any mode is undamped or near aliasing."""
        return bool(np.any(self.undamped) or np.any(self.near_alias))

    def message(self) -> str:
        """One line: the flagged modes, the sample time and what to change ("" if none)."""
        if not self.flagged:
            return ""
        half = 0.5 / self.sample_time
        found, advice = [], []
        if np.any(self.undamped):
            freqs = ", ".join(f"{f:.1f}" for f in self.frequency_hz[self.undamped])
            found.append(f"undamped elastic modes ({freqs} Hz, damping ratio 0)")
            advice.append(
                "an undamped design has no margin for the damping of the real arm: give the "
                "links structural damping (links[i].damping_ratio)"
            )
        near = self.near_alias
        for f, d, k in zip(self.frequency_hz[near], self.distance[near], self.multiple[near]):
            found.append(f"the {f:.1f} Hz mode {100 * d:.2f} % from {k} x fs/2 = {k * half:.1f} Hz")
        if np.any(near):
            advice.append(
                "near a multiple of fs/2 a sampled mode pair is nearly uncontrollable from the "
                "held torque and the design holds only with the damping the model assumes: "
                f"choose a sample time with every mode more than {100 * self.tolerance:g} % of "
                "fs/2 from a multiple of fs/2"
            )
        return (
            f"the design model has {' and '.join(found)} at sample_time "
            f"{1e3 * self.sample_time:g} ms (fs/2 = {half:.1f} Hz); {'; '.join(advice)}"
        )


def sampling_diagnosis(
    model, op: OperatingPoint, sample_time: float, tolerance: float = ALIAS_TOLERANCE
) -> SamplingDiagnosis:
    """The elastic modes of ``model`` linearised at ``op``, judged against ``sample_time``.

    The elastic modes are the ``n_q - n_u`` oscillatory eigenvalue pairs of the
    linearisation with the highest frequencies (a rigid-body pendulum mode under gravity is
    oscillatory too, and slower).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model.
    op : OperatingPoint
        Where the controller is designed.
    sample_time : float
        The controller's sample time, s.
    tolerance : float
        Relative distance from a multiple of ``fs/2`` below which a mode is flagged.

    Returns
    -------
    SamplingDiagnosis
        Empty arrays for a rigid model.
    """
    n_elastic = int(model.n_q - model.n_u)
    A = Linearizer(model, ("joints",)).matrices(op)[0]
    n = A.shape[0]
    summary = modal_summary(control.ss(A, np.zeros((n, 1)), np.zeros((1, n)), 0.0))
    pairs = np.flatnonzero(summary.oscillatory)
    elastic = pairs[len(pairs) - min(n_elastic, len(pairs)) :]
    freqs = np.abs(summary.eigenvalues[elastic].imag) / (2 * np.pi)
    distance, multiple = alias_distance(freqs, sample_time)
    return SamplingDiagnosis(
        freqs,
        summary.damping[elastic],
        float(sample_time),
        distance,
        multiple,
        float(tolerance),
    )


__all__ = [
    "ALIAS_TOLERANCE",
    "UNDAMPED_RATIO",
    "SamplingDiagnosis",
    "alias_distance",
    "sampling_diagnosis",
]
