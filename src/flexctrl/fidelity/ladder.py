"""The cheapest model that meets a scene's tip-accuracy tolerance (issue 7, ``fidelity = "auto"``).

:func:`choose_fidelity` picks, for one ``kind = "arm"`` scene and a tolerance on
the tip position (m), the lowest rung of the ladder ``rigid -> amm:1 -> amm:2 ->
...`` whose tip path is estimated to stay within the tolerance, and measures that
claim against a converged reference.  The method:

1. **Modal-bandwidth rule (starting rung).**  The excitation bandwidth ``B`` is
   the frequency below which ``energy_fraction`` (default 99 %) of the energy of
   the scene's joint torques lies (their spectrum over the scene's duration,
   :func:`excitation_bandwidth`).  Mode ``k`` of link ``i`` (its clamped-mass
   frequency with the rest of the arm as boundary, ``Model.info
   ["link_frequencies_rad_s"]``) is kept when it lies below
   ``bandwidth_factor * B`` (default 5); the starting rung keeps, on every link,
   as many modes as the most demanding link needs.  Without a torque (free
   vibration) the rule gives no bound and the walk starts at the lowest rung
   that holds the scene's initial elastic coordinates (``qf32`` needs ``amm:2``).
2. **Error estimate by the rungs above ("Richardson-like").**  The estimate of
   rung ``N`` is ``safety`` (default 2) times the largest tip distance between
   rung ``N`` and rungs ``N + 1`` and ``N + 2`` (up to the reference model), each
   run with the integrator and step it would be run with.  The factor 2 covers
   geometric convergence whose successive differences shrink at least by half
   (error <= d / (1 - r) <= 2 d for r <= 1/2); the measured ratio of successive
   differences is recorded so a reader can check that assumption.  Two rungs, not
   one, because convergence in modes per link is not monotone: on a slow move the
   first mode per link changes the tip less than the second does, and ``rigid``
   against ``amm:1`` alone underestimated the error by a factor of 2.4.  From the
   starting rung the walk goes *up* while the estimate exceeds the tolerance, or
   *down* while the rung below also meets it; the choice is the lowest rung
   reached whose estimate meets the tolerance.
3. **Reference.**  ``amm:R`` (default ``amm:5``, one rung above the top
   candidate) with RK4 at ``omega_max * dt <= reference_omega_dt`` (default 0.5).
   Its convergence is shown by two refinements: the same model at half the step
   (time) and the rung below at its own step (model); both distances are
   recorded, and a :class:`UserWarning` is issued when either exceeds half the
   tolerance (the reference would then not be fit to judge the choice).  The
   chosen rung's tip distance from the reference is ``reference_error``.
4. **Integrator and step.**  A scene with an implicit integrator (``cvodes``,
   ``idas``, ``scipy``) keeps it and its step.  With ``rk4``, a rung keeps the
   scene's step when ``omega_max * dt <= RK4_MARGIN * RK4_STABILITY_LIMIT`` (RK4's stability limit
   with a 10 % margin); otherwise the step is the scene's divided by the
   smallest whole number that satisfies it, so outputs and torque switching
   still fall on the scene's grid.

Every simulation's wall time (``time.perf_counter``, integration only; model
build and compilation recorded apart) is kept; ``cost_ratio`` is the choice's
integration wall time over the reference's.

This module is the method alone: it runs candidates through the callables it is
given (``run_rung``, ``run_reference`` of :func:`walk_and_judge`) and knows no scene
file, model builder or integrator.  Running scenes for it is
:mod:`flexctrl.scenes.auto`'s job (models, runs and choices kept in a
:class:`~flexctrl.scenes.cache.SceneCache` the caller owns).

Examples
--------
>>> from flexctrl.spec.scene import load_scene
>>> from flexctrl.scenes.auto import choose_fidelity
>>> scene = load_scene("studies/scenes/slow_move_light.toml", ["duration=1.0"])
>>> choice = choose_fidelity(scene, 1e-3, top=2, reference="amm:3")  # doctest: +SKIP
>>> str(choice.choice)  # doctest: +SKIP
'rigid'
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from flexctrl.errors import SpecError
from flexctrl.fidelity.records import (
    FidelityChoice,
    RunRecord,
    ToleranceUnreachable,
    rung_name,
    tip_distance,
)
from flexctrl.fidelity.walk import LINEAR_FACTOR, WALKS, linear_candidate, walk_and_judge
from flexctrl.spec.fidelity import parse_fidelity

IMPLICIT = ("cvodes", "idas", "scipy")


_QF = re.compile(r"^qf(\d+?)(\d)$")


# -- the pieces of the method -----------------------------------------------------------------
def excitation_bandwidth(scene, n_joints: int, *, energy_fraction: float = 0.99) -> float | None:
    """Frequency (Hz) below which ``energy_fraction`` of the scene's torque energy lies.

    The torques of ``scene.input`` are sampled at the scene's step (refined to at
    most 0.1 ms) over the scene's duration, zero-padded to four times that length,
    and their energy spectrum summed over joints.

    Parameters
    ----------
    scene : ArmScene
    n_joints : int
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
    n_fft = 1 << int(math.ceil(math.log2(4 * n)))
    spectrum = np.sum(np.abs(np.fft.rfft(torque, n=n_fft, axis=0)) ** 2, axis=1)
    spectrum[1:] *= 2.0  # one-sided
    cumulative = np.cumsum(spectrum) / spectrum.sum()
    freqs = np.fft.rfftfreq(n_fft, h)
    return float(freqs[min(int(np.searchsorted(cumulative, energy_fraction)), freqs.size - 1)])


# -- closed-loop scenes -------------------------------------------------------------------------
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

    Returns
    -------
    float or None
        None when the torques are constant.
    """
    torque = np.asarray(torque, dtype=float)
    torque = torque - torque.mean(axis=0)
    if not np.any(torque):
        return None
    n = torque.shape[0]
    n_fft = 1 << int(math.ceil(math.log2(4 * n)))
    spectrum = np.sum(np.abs(np.fft.rfft(torque, n=n_fft, axis=0)) ** 2, axis=1)
    spectrum[1:] *= 2.0
    cumulative = np.cumsum(spectrum) / spectrum.sum()
    freqs = np.fft.rfftfreq(n_fft, h)
    return float(freqs[min(int(np.searchsorted(cumulative, energy_fraction)), freqs.size - 1)])


def required_modes(scene) -> int:
    """Fewest modes per link that hold the scene's initial elastic coordinates (``qf<link><mode>``)."""
    need = 0
    for name in scene.qf0:
        match = _QF.match(name)
        if match:
            need = max(need, int(match.group(2)))
    return need


def check_ladder(top, reference, safety, energy_fraction, bandwidth_factor, reference_omega_dt):
    """Validate the chooser's options (shared by the arm and closed-loop choosers); returns the reference fidelity."""
    if isinstance(top, bool) or not isinstance(top, int) or not 1 <= top <= 5:
        raise SpecError(
            f"value {top!r} is not allowed; allowed: an integer 1..5 (amm:top is the highest candidate)",
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
            f"value {tol!r} is not allowed; allowed: a finite number > 0 (m, tip-position tolerance)",
            source=source,
            key=key,
        )
    return float(tol)


__all__ = [
    "IMPLICIT",
    "LINEAR_FACTOR",
    "WALKS",
    "FidelityChoice",
    "RunRecord",
    "ToleranceUnreachable",
    "check_ladder",
    "check_tolerance",
    "excitation_bandwidth",
    "linear_candidate",
    "required_modes",
    "rung_name",
    "sampled_bandwidth",
    "tip_distance",
    "walk_and_judge",
]
