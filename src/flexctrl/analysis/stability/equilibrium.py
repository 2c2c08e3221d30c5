"""The equilibrium a stability probe perturbs: the state checked and refined, linearised, its modes.

:func:`refine_equilibrium` settles the elastic coordinates of a state held by constant
torques, :func:`linearize` gives ``f`` and ``A = df/dx`` there, and :func:`modal_basis` the
vibration modes a probe watches (eigenvalues, right eigenvectors and the rows of the left
ones that give the modal amplitudes).  Units: SI.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import casadi as ca
import numpy as np
import scipy.linalg

from flexctrl.analysis.stability.theory import classify_eigenvalues
from flexctrl.dynamics.jacobians import jacobian_function
from flexctrl.dynamics.parametric import try_expand
from flexctrl.errors import SimulationError, SpecError


def linearization_function(model) -> ca.Function:
    """``(x, u) -> (f, A = df/dx)`` of the model's forward dynamics (free joints, torques held),
    expanded to SX.

    :func:`flexctrl.dynamics.jacobians.jacobian_function`, the one Jacobian builder.
    """
    return try_expand(jacobian_function(model, value=True))


def linearize(
    model, x0: np.ndarray, u0: np.ndarray, function: ca.Function | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(f(x0, u0), A = df/dx(x0, u0))``; pass ``function`` (:func:`linearisation_function`) to
    reuse it."""
    f, A = (function or linearization_function(model))(x0, u0)
    return np.asarray(f, dtype=float).ravel(), np.asarray(A, dtype=float)


def refine_equilibrium(
    model,
    x0: np.ndarray,
    u0: np.ndarray,
    *,
    tolerance: float,
    max_iterations: int = 8,
    function: ca.Function | None = None,
) -> tuple[np.ndarray, float]:
    """Newton on ``f(x, u0) = 0`` from ``x0`` (least squares where ``A`` is singular); returns ``(x,
    max|f|)``.

    Parameters
    ----------
    tolerance
        Largest acceptable remaining Newton step (m or rad): the offset of the
        true equilibrium from the returned state, in the linear model.

    Raises
    ------
    SpecError
        If ``x0`` is not near an equilibrium: Newton moves it by more than 1 %
        of ``1 + max|x0|`` or cannot bring the step below ``tolerance``.
    """
    function = function or linearization_function(model)
    x = np.array(x0, dtype=float)
    f, A = linearize(model, x, u0, function)
    start = float(np.max(np.abs(f), initial=0.0))
    step_size = math.inf
    for _ in range(max_iterations):
        step = np.linalg.lstsq(A, -f, rcond=None)[0]
        step_size = float(np.max(np.abs(step), initial=0.0))
        if step_size <= 1e-3 * tolerance:
            break
        x = x + step
        f, A = linearize(model, x, u0, function)
    residual = float(np.max(np.abs(f), initial=0.0))
    moved = float(np.max(np.abs(x - x0)))
    if moved > 1e-2 * (1.0 + float(np.max(np.abs(x0)))) or step_size > tolerance:
        raise SpecError(
            f"the state is not an equilibrium: max |f(x0, u0)| = {start:.3g}; Newton moved it by "
            f"{moved:.3g} and its last step is {step_size:.3g} (allowed: {tolerance:.3g}); "
            "allowed: a static equilibrium with its holding torques, e.g. "
            "flexctrl.linear.equilibrium(model, q_joints)",
            key="x0",
        )
    return x, residual


def modal_basis(A: np.ndarray, n_q: int, tol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Watched eigenvalues, their normalised right eigenvectors (columns) and modal projection
    rows."""
    lam, left, right = scipy.linalg.eig(A, left=True, right=True)
    kind, _snapped, _w = classify_eigenvalues(lam, tol)
    keep = [i for i in range(lam.size) if kind[i] in ("undamped", "damped") and lam[i].imag >= 0]
    vectors, rows = [], []
    for i in keep:
        v = right[:, i]
        k = int(np.argmax(np.abs(v[:n_q])))
        v = v / v[k]  # largest coordinate = 1 (real)
        w = left[:, i]
        rows.append(w.conj() / (w.conj() @ v))
        vectors.append(v)
    return lam[keep], np.array(vectors).T, np.array(rows)


def checked_state(
    model: Any, x0: Sequence[float], u0: Sequence[float] | None
) -> tuple[np.ndarray, np.ndarray]:
    """``(x0, u0)`` as finite arrays of the model's sizes (``u0`` default: zero torques)."""
    x = np.asarray(x0, dtype=float).ravel()
    u = np.zeros(model.n_u) if u0 is None else np.asarray(u0, dtype=float).ravel()
    if (
        x.shape != (model.n_x,)
        or u.shape != (model.n_u,)
        or not (np.all(np.isfinite(x)) and np.all(np.isfinite(u)))
    ):
        raise SpecError(
            f"x0 has shape {x.shape}, u0 {u.shape}; expected {model.n_x} and "
            f"{model.n_u} finite values",
            key="x0",
        )
    return x, u


def check_spectrum(model: Any, eigenvalues: np.ndarray, omega_max: float) -> None:
    """Refuse a linearisation without a vibration mode or with a physically growing one."""
    if not omega_max > 0:
        raise SimulationError(
            f"the linearisation of '{model.name}' at this state has no vibration mode "
            "(omega_max = 0), so there is no step scale to search; use a flexible fidelity "
            "or a configuration under load"
        )
    kind, _snapped, _w = classify_eigenvalues(eigenvalues)
    if np.any(kind == "growing"):
        rates = np.sort(eigenvalues.real[kind == "growing"])[::-1]
        raise SpecError(
            f"the equilibrium is unstable: {rates.size} eigenvalues of df/dx grow physically "
            f"(rates up to {rates[0]:.4g} 1/s), and over a probe they would swamp the modes "
            "being watched; allowed: a stable equilibrium (e.g. hanging, or joints held "
            "where gravity does not tip the arm over)",
            key="x0",
        )
