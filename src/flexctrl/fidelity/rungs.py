"""The automatic-fidelity walk's pieces: rungs, bandwidths, tip distances, option checks.

The method they serve is described in :mod:`flexctrl.fidelity.ladder`.
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from flexctrl.errors import SpecError
from flexctrl.fidelity.records import RunRecord
from flexctrl.sim.tip_error import TipError, tip_error
from flexctrl.spec.fidelity import Fidelity, parse_fidelity

#: Integrators a rung keeps with the scene's step (method step 4); ``rk4`` gets a stable step.
IMPLICIT = ("cvodes", "idas", "scipy")

_QF = re.compile(r"^qf(\d+?)(\d)$")


def rung_name(n: int) -> str:
    """The fidelity of rung ``n``: ``rigid`` for 0, else ``amm:n`` (modes per link)."""
    return "rigid" if n == 0 else f"amm:{n}"


def required_modes(scene) -> int:
    """Fewest modes per link that hold the scene's initial elastic coordinates (``qf<link><k>``)."""
    need = 0
    for name in scene.qf0:
        match = _QF.match(name)
        if match:
            need = max(need, int(match.group(2)))
    return need


def tip_distance(a: RunRecord, b: RunRecord) -> TipError:
    """Tip distance (m) of ``b`` from ``a`` on the finer run's samples; infinite if one diverged."""
    if a.diverged_at is not None or b.diverged_at is not None:
        return TipError(rms=math.inf, max=math.inf)
    first, second = (a, b) if a.dt <= b.dt else (b, a)
    return tip_error(first.time, first.tip, second.time, second.tip)


def excitation_bandwidth(scene, n_joints: int, *, energy_fraction: float = 0.99) -> float | None:
    """Frequency (Hz) below which ``energy_fraction`` of the scene's torque energy lies.

    The torques of ``scene.input`` are sampled at the scene's step (refined to at
    most 0.1 ms) over the scene's duration, zero-padded to four times that length,
    and their energy spectrum summed over joints.

    Parameters
    ----------
    scene : ArmScene
        An open-loop arm scene.
    n_joints : int
        Joints of the arm.
    energy_fraction : float
        In (0, 1).

    Returns
    -------
    float or None
        The bandwidth (Hz), or None when the scene applies no torque.
    """
    k = max(1, math.ceil(scene.dt / 1e-4 - 1e-9))
    h = scene.dt / k
    n = max(2, int(math.ceil(scene.duration / h - 1e-9)))
    torque = scene.input.torque((np.arange(n) + 0.5) * h, n_joints)
    if not np.any(torque):
        return None
    return _bandwidth(torque, h, energy_fraction)


def sampled_bandwidth(
    torque: np.ndarray, h: float, *, energy_fraction: float = 0.99
) -> float | None:
    """Frequency (Hz) below which ``energy_fraction`` of sampled torques' energy lies.

    Parameters
    ----------
    torque : numpy.ndarray
        Torques (N m), shape (T, n_joints), sampled every ``h`` s; their mean is removed
        first (a held final torque is no excitation), then they are zero-padded to four
        times their length.
    h : float
        Sample period (s).
    energy_fraction : float
        In (0, 1).

    Returns
    -------
    float or None
        None when the torques are constant.
    """
    torque = np.asarray(torque, dtype=float)
    torque = torque - torque.mean(axis=0)
    if not np.any(torque):
        return None
    return _bandwidth(torque, h, energy_fraction)


def _bandwidth(torque: np.ndarray, h: float, energy_fraction: float) -> float:
    """The frequency (Hz) below which ``energy_fraction`` of the torques' spectrum lies."""
    n = torque.shape[0]
    n_fft = 1 << int(math.ceil(math.log2(4 * n)))
    spectrum = np.sum(np.abs(np.fft.rfft(torque, n=n_fft, axis=0)) ** 2, axis=1)
    spectrum[1:] *= 2.0  # one-sided
    cumulative = np.cumsum(spectrum) / spectrum.sum()
    freqs = np.fft.rfftfreq(n_fft, h)
    return float(freqs[min(int(np.searchsorted(cumulative, energy_fraction)), freqs.size - 1)])


def check_ladder(
    top, reference, safety, energy_fraction, bandwidth_factor, reference_omega_dt
) -> Fidelity:
    """Validate the chooser's options (shared by the arm and closed-loop choosers).

    Returns
    -------
    Fidelity
        The reference model (default ``amm:(top + 1)``).

    Raises
    ------
    SpecError
        Naming the option, its value and what is allowed.
    """
    if isinstance(top, bool) or not isinstance(top, int) or not 1 <= top <= 5:
        raise SpecError(
            f"value {top!r} is not allowed; allowed: an integer 1..5 (amm:top is the highest "
            "candidate)",
            key="top",
        )
    ref = parse_fidelity(reference if reference is not None else f"amm:{top + 1}", key="reference")
    if ref.kind != "amm" or not top < (ref.count or 0) <= 6:
        raise SpecError(
            f"value '{ref}' is not allowed; allowed: 'amm:R' with {top} < R <= 6 (above the top "
            f"candidate amm:{top})",
            key="reference",
        )
    for name, value, low, high in (
        ("safety", safety, 1.0, 100.0),
        ("energy_fraction", energy_fraction, 0.0, 1.0),
        ("bandwidth_factor", bandwidth_factor, 0.0, 1e3),
        ("reference_omega_dt", reference_omega_dt, 0.0, 2.5),
    ):
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not low <= value <= high
            or value == 0
        ):
            raise SpecError(
                f"value {value!r} is not allowed; allowed: a number in ({low:g}, {high:g}]",
                key=name,
            )
    return ref


def check_tolerance(tol: Any, *, source: str | None = None, key: str = "tolerance") -> float:
    """``tol`` as a float if it is a finite number > 0 (m), else :class:`SpecError`."""
    if (
        isinstance(tol, bool)
        or not isinstance(tol, (int, float))
        or not math.isfinite(tol)
        or tol <= 0
    ):
        raise SpecError(
            f"value {tol!r} is not allowed; allowed: a finite number > 0 (m, tip-position "
            "tolerance)",
            source=source,
            key=key,
        )
    return float(tol)
