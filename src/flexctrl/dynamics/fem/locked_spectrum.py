"""Frequencies of a model and the fixed RK4 step they allow.

The locked-joint frequencies of the finite-element arm and of the assumed-modes model, and the
free-joint spectral radius.

Computed from the models' ``M`` and ``K`` (:func:`flexctrl.dynamics.fem.fem_arm.locked_matrices`)
and the Jacobian of ``f``; used by ``tools/fem_report.py`` (the figures of
the finite-element explanation) and :mod:`flexctrl.analysis.simulation_methods` (the
speed/accuracy study).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import casadi as ca
import numpy as np

from flexctrl.dynamics.build import build_model
from flexctrl.dynamics.fem.fem_arm import generalized_frequencies, locked_matrices
from flexctrl.spec.arm import ArmSpec


def locked_fem_hz(
    arm: ArmSpec, n_elements: int, q_deg: Sequence[float], n_modes: int = 6
) -> np.ndarray:
    """Lowest locked-joint frequencies (Hz) of the FE arm, links straight, no gravity.

    Parameters
    ----------
    arm : ArmSpec
        The arm.
    n_elements : int
        Elements per link.
    q_deg : sequence of float
        Joint angles, degrees.
    n_modes : int
        Frequencies returned.

    Returns
    -------
    ndarray
        ``n_modes`` frequencies, Hz, ascending.
    """
    M, K = locked_matrices(arm, n_elements, np.radians(q_deg))
    return generalized_frequencies(K, M)[:n_modes] / (2 * math.pi)


def locked_amm_hz(
    arm: ArmSpec, n_modes_per_link: int, q_deg: Sequence[float], n_modes: int = 6
) -> np.ndarray:
    """Lowest locked-joint frequencies (Hz) of the assumed-modes model, modes frozen at ``q``.

    Parameters
    ----------
    arm : ArmSpec
        The arm.
    n_modes_per_link : int
        Assumed modes per link.
    q_deg : sequence of float
        Joint angles, degrees.
    n_modes : int
        Frequencies returned.

    Returns
    -------
    ndarray
        ``n_modes`` frequencies, Hz, ascending.
    """
    q = np.radians(q_deg)
    model = build_model(arm, f"amm:{n_modes_per_link}", reference_q=q)
    n = model.n_joints
    M = model.mass_matrix(np.concatenate([q, np.zeros(model.n_q - n)]))[n:, n:]
    K = np.array(model.functions["K"]()["K"])[n:, n:]
    return generalized_frequencies(K, 0.5 * (M + M.T))[:n_modes] / (2 * math.pi)


def free_joint_radius(model) -> float:
    """Spectral radius of ``df/dx`` at rest at the reference configuration (rad/s), joints free.

    With free joints the hub modes can exceed the locked ``omega_max`` (5 % at 8
    elements per link for the three-link arm).
    """
    x, u = ca.MX.sym("x", model.n_x), ca.MX.sym("u", model.n_u)
    jac = ca.Function("J", [x, u], [ca.jacobian(model.functions["f"](x, u), x)])
    x0 = np.zeros(model.n_x)
    x0[: model.n_joints] = model.info.get("reference_q", np.zeros(model.n_joints))
    return float(
        np.max(np.abs(np.linalg.eigvals(np.asarray(jac(x0, np.zeros(model.n_u)), dtype=float))))
    )


def rk4_step_for(model, sample: float, safety: float = 2.4) -> int:
    """Substeps per sample with ``omega h <= safety`` at the model's fastest frequency.

    That is the larger of the locked ``omega_max`` and the free-joint spectral radius (RK4's
    limit on the imaginary axis is 2.83).

    Parameters
    ----------
    model : Model
        The model stepped.
    sample : float
        Output sample, s.
    safety : float
        The largest ``omega h`` allowed.

    Returns
    -------
    int
        Substeps per sample, >= 1.
    """
    omega = max(float(model.omega_max), free_joint_radius(model))
    return max(1, math.ceil(sample * omega / safety))
