"""The cheapest model that meets a scene's tip-accuracy tolerance (``fidelity = "auto"``).

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
   first mode per link can change the tip less than the second does, so ``rigid``
   against ``amm:1`` alone can underestimate the error.  From the
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
   scene's step when ``omega_max * dt <= RK4_MARGIN * RK4_STABILITY_LIMIT`` (RK4's
   stability limit with a 10 % margin); otherwise the step is the scene's divided by the
   smallest whole number that satisfies it, so outputs and torque switching
   still fall on the scene's grid.

Every simulation's wall time (``time.perf_counter``, integration only; model
build and compilation recorded apart) is kept; ``cost_ratio`` is the choice's
integration wall time over the reference's.

For a closed loop the default walk (``fidelity_walk = "estimate"``) first estimates the
rungs on linearised plants (:mod:`flexctrl.fidelity.linear_candidate`) and certifies the
lowest one they cannot exclude, or, for a controller stepped in Python, walks down from
the top rung; both judge against the reference model at its own step and estimate its
step error linearly (:mod:`flexctrl.fidelity.walk`).

The package is the method alone: it runs candidates through the callables it is given
(:class:`~flexctrl.fidelity.walk.Runners`) and knows no scene file, model builder or
integrator.  Running scenes for it is the job of :mod:`flexctrl.scenes.auto` (arm scenes)
and :mod:`flexctrl.scenes.auto_closed_loop` (closed loops), with models, runs and choices
kept in a :class:`~flexctrl.scenes.cache.SceneCache` the caller owns.  This module gathers
the names the rest of the toolkit uses: the records (:mod:`flexctrl.fidelity.records`),
the pieces (:mod:`flexctrl.fidelity.rungs`) and the walk.

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

from flexctrl.fidelity.linear_candidate import LINEAR_FACTOR, linear_candidate
from flexctrl.fidelity.records import FidelityChoice, RunRecord, ToleranceUnreachable
from flexctrl.fidelity.rungs import (
    IMPLICIT,
    check_ladder,
    check_tolerance,
    excitation_bandwidth,
    required_modes,
    rung_name,
    sampled_bandwidth,
    tip_distance,
)
from flexctrl.fidelity.walk import (
    METHOD,
    METHOD_ESTIMATE,
    METHOD_FROM_TOP,
    WALK_KINDS,
    Ladder,
    Runners,
    walk_and_judge,
)
from flexctrl.spec.fidelity import FIDELITY_WALKS

#: The walks of the closed-loop chooser (:data:`flexctrl.spec.fidelity.FIDELITY_WALKS`).
WALKS = FIDELITY_WALKS

__all__ = [
    "IMPLICIT",
    "LINEAR_FACTOR",
    "METHOD",
    "METHOD_ESTIMATE",
    "METHOD_FROM_TOP",
    "WALKS",
    "WALK_KINDS",
    "FidelityChoice",
    "Ladder",
    "RunRecord",
    "Runners",
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
