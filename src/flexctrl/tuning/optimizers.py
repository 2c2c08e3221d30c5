"""The optimisers a tuning can use, behind one driver interface.

Every optimiser searches the unit box ``[0, 1]^d`` (each tuned key mapped linearly, or
on ``log10`` for ``scale = "log"``, from its bounds) and is handed ``evaluate(batch) ->
scores``, which runs a whole batch of candidates in parallel on the study backend.  They
are deterministic for a given seed, so a killed tuning replays the same candidates and
finds their runs in the store.

``differential_evolution``
    :func:`scipy.optimize.differential_evolution` (``updating="deferred"``: one generation
    is one batch, through its ``workers`` map), Latin-hypercube start with the file's own
    values as the first member, no gradient polish.  Global, robust to the flat penalty
    plateaus that unstable candidates make, needs no smoothness.
``cma``
    CMA-ES (the ``cma`` package, Hansen's reference implementation): ``ask`` a
    generation, evaluate it as one batch, ``tell``; bounded by the package's own
    boundary handling, start at the file's values with step 0.3 of the box.
``nelder_mead``
    :func:`scipy.optimize.minimize` with Nelder-Mead from the file's values: local and
    sequential (a batch of one), the cheapest when the start is good.

``docs/guide/tune-a-controller.md`` compares the three on the same tuning problem.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from flexctrl.errors import SpecError

Evaluate = Callable[[Sequence[np.ndarray]], list[float]]


class BudgetSpent(Exception):
    """Raised by a batch evaluator when the tuning's evaluation budget is used up."""


def minimize(
    method: str, evaluate: Evaluate, x0: np.ndarray, budget: int, population: int, seed: int
) -> None:
    """Run ``method`` on the unit box from ``x0`` until ``budget`` candidates were evaluated (or it
    converged).

    Parameters
    ----------
    method : {"differential_evolution", "cma", "nelder_mead"}
    evaluate : callable
        ``evaluate(list of points) -> list of scores``; may raise :class:`BudgetSpent`.
    x0 : ndarray
        Start, in the unit box.
    budget : int
        Candidates to evaluate at most.
    population : int
        Candidates per generation (batch size) for the population methods.
    seed : int
    """
    runners = {
        "differential_evolution": _differential_evolution,
        "cma": _cma,
        "nelder_mead": _nelder_mead,
    }
    if method not in runners:
        raise SpecError(
            f"value {method!r} is not allowed; allowed: {', '.join(map(repr, runners))}",
            key="method",
        )
    x0 = np.clip(np.asarray(x0, dtype=float), 0.0, 1.0)
    try:
        runners[method](evaluate, x0, budget, population, seed)
    except BudgetSpent:
        pass


def _differential_evolution(
    evaluate: Evaluate, x0: np.ndarray, budget: int, population: int, seed: int
) -> None:
    from scipy.optimize import differential_evolution

    d = x0.size
    multiplier = max(
        1, math.ceil(population / d)
    )  # scipy's population is multiplier x d, at least 5
    size = max(5, multiplier * d)
    generations = max(0, math.ceil(budget / size) - 1)

    # atol = -1: scipy's convergence test (std of the scores <= atol + tol |mean|) never fires, so a
    # population stuck on one penalty plateau keeps searching until the budget is spent
    def batch_map(_function, points):
        return evaluate([np.asarray(p, dtype=float) for p in points])

    differential_evolution(
        lambda x: 0.0,
        [(0.0, 1.0)] * d,
        popsize=multiplier,
        maxiter=generations,
        seed=seed,
        polish=False,
        tol=0.0,
        atol=-1.0,
        init="latinhypercube",
        x0=x0,
        updating="deferred",
        workers=batch_map,
    )


def _cma(evaluate: Evaluate, x0: np.ndarray, budget: int, population: int, seed: int) -> None:
    try:
        import cma
    except ImportError as exc:  # pragma: no cover - a dependency of the package
        raise SpecError(
            "method 'cma' needs the cma package (pip install cma)", key="method"
        ) from exc

    options = {
        "bounds": [0.0, 1.0],
        "popsize": max(2, population),
        "seed": seed + 1,
        "verbose": -9,
        "maxfevals": budget,
        "tolx": 1e-6,
        "tolfun": 0.0,
        "tolflatfitness": 10**9,
    }
    es = cma.CMAEvolutionStrategy(list(x0), 0.3, options)
    used = 0
    while not es.stop() and used + es.popsize <= budget:  # whole generations only (tell needs them)
        points = es.ask()
        scores = evaluate([np.asarray(p, dtype=float) for p in points])
        used += len(points)
        es.tell(points, scores)


def _nelder_mead(
    evaluate: Evaluate, x0: np.ndarray, budget: int, population: int, seed: int
) -> None:
    from scipy.optimize import minimize as scipy_minimize

    scipy_minimize(
        lambda x: evaluate([np.asarray(x, dtype=float)])[0],
        x0,
        method="Nelder-Mead",
        bounds=[(0.0, 1.0)] * x0.size,
        options={"maxfev": budget, "xatol": 1e-4, "fatol": 0.0},
    )
