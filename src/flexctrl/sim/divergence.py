"""Divergence detection for :class:`~flexctrl.sim.integrator.Integrator` runs, chunk by chunk.

A run has diverged when a state or output is not finite, or when the kinetic
plus elastic energy exceeds ``energy_factor`` (100 by default) times what the
run can account for: the initial kinetic and elastic energy, the range of
gravitational energy seen so far (a running range, so a diverging sample cannot
raise its own allowance), the work the joint torques did (``|u . dq|`` summed)
and a floor of 1e-6 J.  Without numerical error the ratio stays at or below 1.
The error names the earliest offending time, the step, ``omega_max`` and a
stable step or another integrator (:meth:`Integrator.stability_advice`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from flexctrl.errors import SimulationError

if TYPE_CHECKING:  # pragma: no cover
    from flexctrl.sim.integrator import Integrator


class DivergenceMonitor:
    """Per-chunk checks: finite states and outputs, bounded kinetic plus elastic energy.

    Parameters
    ----------
    integrator : Integrator
        The integrator checked (its ``energy_factor`` sets the bound).
    x0 : numpy.ndarray
        Initial state.
    y0 : numpy.ndarray
        Initial outputs; the first three rows are ``E_kin``, ``E_el``, ``E_grav`` (J).
    """

    FLOOR_J = 1e-6

    def __init__(self, integrator: Integrator, x0: np.ndarray, y0: np.ndarray):
        self.integrator = integrator
        self.x0 = x0
        self.reference = abs(y0[0]) + abs(y0[1])
        self.grav_low = self.grav_high = float(y0[2])
        self.work_abs = 0.0

    def check(self, times: np.ndarray, X: np.ndarray, Y: np.ndarray, U: np.ndarray) -> None:
        """``X``: the chunk's start state and its k states; ``Y``, ``times``: the k new samples."""
        with np.errstate(
            over="ignore", invalid="ignore"
        ):  # huge but finite states are what we look for
            self._check(times, X, Y, U)

    def _check(self, times: np.ndarray, X: np.ndarray, Y: np.ndarray, U: np.ndarray) -> None:
        new = X[1:]
        bad = ~(np.all(np.isfinite(new), axis=1) & np.all(np.isfinite(Y), axis=1))
        first_bad = int(np.argmax(bad)) if bad.any() else len(times)
        good = slice(0, first_bad)
        # running (not chunk-wide) range of E_grav: a diverging sample must not raise its own budget
        low = np.minimum.accumulate(np.minimum(Y[good, 2], self.grav_low))
        high = np.maximum.accumulate(np.maximum(Y[good, 2], self.grav_high))
        if first_bad > 0:
            self.grav_low, self.grav_high = float(low[-1]), float(high[-1])
        n_u = U.shape[1]
        work = np.abs(np.einsum("ij,ij->i", U[good], np.diff(X[: first_bad + 1, :n_u], axis=0)))
        available = self.reference + (high - low) + self.FLOOR_J + self.work_abs + np.cumsum(work)
        self.work_abs += float(work.sum())
        energy = Y[good, 0] + Y[good, 1]
        over = energy > self.integrator.energy_factor * available
        if over.any():
            i = int(np.argmax(over))
            self._fail(
                times[i],
                f"kinetic plus elastic energy grew to {energy[i]:.3g} J, more than "
                f"{self.integrator.energy_factor:g} times the {available[i]:.3g} J the run can "
                "account for",
            )
        if bad.any():
            self._fail(times[first_bad], "the state became non-finite (NaN or inf)")

    def _fail(self, t: float, what: str) -> None:
        it = self.integrator
        raise SimulationError(
            f"simulation diverged at t = {t:.6g} s with {it.name} step dt = {it.dt:g} s: {what}. "
            + it.stability_advice((self.x0,))
        )
