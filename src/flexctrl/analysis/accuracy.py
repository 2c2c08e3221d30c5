"""Speed against accuracy: simulation methods, a converged reference, tip errors and the Pareto
front.

A *method* is one way of simulating a scene: a model (fidelity and, for assumed
modes, frozen or configuration-scheduled mode shapes) and an integrator with its
step or tolerance.  Methods are spelt as one string (a grid value of the
``speed_vs_accuracy`` study)::

    FIDELITY[+sched]/INTEGRATOR[:VARIANT][@VALUE]

    rigid/rk4@1ms            RK4, step 1 ms
    amm:2/rk4@0.25ms         RK4, 4 steps per 1 ms output sample
    amm:2+sched/rk4@1ms      configuration-scheduled assumed modes
    fem:4/rk4@stable         RK4 at the largest safe step: omega h <= 2.4 for the larger
                             of omega_max and the free-joint spectral radius
    fem:4/newmark@1ms        trapezoidal Newmark, Hessian-of-potential Newton tangents
    amm:2/cvodes@1e-6        CVODES (BDF), rtol 1e-6, atol 1e-2 rtol
    fem:2/idas@1e-5          IDAS (BDF), rtol 1e-5
    amm:2/scipy:DOP853@1e-6  scipy.integrate.solve_ivp, method DOP853, rtol 1e-6

Steps are written ``1ms``, ``250us`` or in seconds (``1e-3``).  Every method
reports its state on the same output grid (``output_dt``, 1 ms); fixed-step
methods take a whole number of steps per output sample.

All methods advance through :class:`Stepper` objects: ``advance(x, u, t0, n)``
holds the torque ``u`` for ``n`` output samples and returns the ``n`` states.  An
open-loop scene is a few such calls (one per constant piece of the torque); a
closed-loop scene one per controller sample.  The wall time of a run is the sum of
the ``advance`` calls only: model building, compilation (cached on disk) and
controller computations are excluded, so ``wall_per_sim_s`` is the integration cost
a user pays per simulated second once the model is built.

Why not the :class:`~flexctrl.sim.integrator.Integrator` classes directly?  Their output
grid is their step, so RK4 on a stiff finite-element model (steps of a few
microseconds) would keep hundreds of thousands of states; here RK4 substeps inside
one compiled call per output sample (as ``rk4_sampler`` of ``tools/fem_report.py``).
CVODES, IDAS and scipy are the package's own integrators (their ``_advance`` hook,
which already integrates a block of held torques); Newmark is
:func:`flexctrl.dynamics.fem.newmark_dae.simulate` on
:func:`flexctrl.dynamics.fem.newmark.model_dae_problem`.

The reference
-------------
A converged tip path per (scene, payload, configuration): the finest affordable
finite-element model with RK4 at its stability-limited step (see
``docs/explanation/speed-and-accuracy.md`` for why not a tight implicit integrator: IDAS at rtol
1e-8 took 70 s per 0.1 s on ``fem:4``).  Its convergence is shown, not assumed:
:func:`compute_reference` also runs the same model with half the step (time discretisation) and
coarser meshes (spatial discretisation) and records their tip distances from the reference.
References are cached on disk as ``.npz``, keyed by a hash of everything that determines them
(:func:`reference_key`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.analysis.simulation_methods import Method
from flexctrl.analysis.steppers import MethodRun

#: Bumped when the numerics of a reference change (part of the cache key).
REFERENCE_VERSION = 1

# -- the Pareto front ----------------------------------------------------------------------


def pareto_front(cost: Sequence[float], error: Sequence[float]) -> np.ndarray:
    """Which points are Pareto-optimal (no other point is at least as cheap and as accurate, and
    better in one).

    Parameters
    ----------
    cost, error : sequence of float
        One value per point (lower is better in both); non-finite points are never on the front.

    Returns
    -------
    numpy.ndarray of bool

    Examples
    --------
    >>> pareto_front([1, 2, 3, 2], [3, 1, 0.5, 2]).tolist()
    [True, True, True, False]
    """
    c, e = np.asarray(cost, dtype=float), np.asarray(error, dtype=float)
    if c.shape != e.shape or c.ndim != 1:
        raise ValueError(f"cost and error need the same 1-D shape; got {c.shape} and {e.shape}")
    ok = np.isfinite(c) & np.isfinite(e)
    front = np.zeros(c.size, dtype=bool)
    for i in np.flatnonzero(ok):
        others = ok.copy()
        others[i] = False
        dominated = others & (c <= c[i]) & (e <= e[i]) & ((c < c[i]) | (e < e[i]))
        front[i] = not dominated.any()
    return front


# -- the reference -------------------------------------------------------------------------


def cache_root() -> Path:
    """``$FLEXCTRL_CACHE/accuracy`` or ``./.flexctrl-cache/accuracy``."""
    from flexctrl.user_cache import cache_directory

    return Path(cache_directory()) / "accuracy"


def reference_key(description: dict[str, Any]) -> str:
    """24 hex digits of sha256 of the canonical JSON of ``description`` plus
    :data:`REFERENCE_VERSION`."""
    text = json.dumps(
        {**description, "version": REFERENCE_VERSION},
        sort_keys=True,
        separators=(",", ":"),
        default=str,
    )
    return hashlib.sha256(text.encode()).hexdigest()[:24]


@dataclass(frozen=True)
class Reference:
    """A reference tip path with its convergence evidence.

    Attributes
    ----------
    time, tip : ndarray
        Output times (s) and tip positions (m).
    method : str
        The reference method's spelling.
    checks : dict
        ``name -> {"method", "rms", "max", "wall_s"}``: tip distance (m) of each
        convergence run from the reference (``"step/2"``: same model, half step;
        ``"fem:N"``: another mesh with RK4 at its stable step).
    wall_s : float
        Integration time of the reference run (s).
    """

    time: np.ndarray
    tip: np.ndarray
    method: str
    checks: dict[str, dict[str, Any]]
    wall_s: float

    def save(self, path: Path) -> None:
        """Write an ``.npz`` (atomically: temporary name, then rename)."""
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp.npz")
        meta = json.dumps({"method": self.method, "checks": self.checks, "wall_s": self.wall_s})
        np.savez_compressed(tmp, time=self.time, tip=self.tip, meta=np.array(meta))
        os.replace(tmp, path)

    @classmethod
    def load(cls, path: Path) -> Reference:
        """Read what :meth:`save` wrote."""
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            return cls(
                np.asarray(data["time"]),
                np.asarray(data["tip"]),
                meta["method"],
                meta["checks"],
                float(meta["wall_s"]),
            )


def compute_reference(
    simulate: Callable[[Method], MethodRun], method: Method, meshes: Sequence[str] = ()
) -> Reference:
    """Run the reference ``method`` and its convergence checks through ``simulate(method) ->
    MethodRun``.

    Checks: the same model with the step halved (``"step/2"``), and each fidelity in
    ``meshes`` with the reference's integrator (coarser meshes show the spatial
    convergence; a finer one bounds the reference's own error).
    """
    from flexctrl.sim.tip_error import tip_error

    ref = simulate(method)
    checks: dict[str, dict[str, Any]] = {}
    candidates = [("step/2", method.refined())] + [
        (m, dataclasses.replace(method, fidelity=m)) for m in meshes
    ]
    for name, other in candidates:
        run = simulate(other)
        err = tip_error(ref.time, ref.tip, run.time, run.tip)
        checks[name] = {"method": other.label, "rms": err.rms, "max": err.max, "wall_s": run.wall_s}
    return Reference(ref.time, ref.tip, method.label, checks, ref.wall_s)


def cached_reference(
    key_data: dict[str, Any], build: Callable[[], Reference], directory: Path | None = None
) -> tuple[Reference, Path, bool]:
    """The reference for ``key_data`` from the disk cache, or ``build()`` it and store it.

    Returns
    -------
    reference, path, hit
    """
    directory = cache_root() if directory is None else Path(directory)
    path = directory / f"reference_{reference_key(key_data)}.npz"
    if path.is_file():
        try:
            return Reference.load(path), path, True
        except (OSError, ValueError, KeyError):
            pass  # unreadable (e.g. a half-written file from a killed run): recompute
    ref = build()
    ref.save(path)
    (path.with_suffix(".json")).write_text(
        json.dumps(
            {"key": key_data, "method": ref.method, "checks": ref.checks}, indent=1, default=str
        )
    )
    return ref, path, False
