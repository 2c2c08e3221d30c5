"""Facts read off a model for its linearisation: signal names, stiffness, torque limits.

Names follow the state ``x = (q, qd)``: the coordinates ``q1.., qf11..``, then their rates
``dq1.., dqf11..``; the inputs are the joint torques ``tau1..`` (N m).
"""

from __future__ import annotations

import math
from typing import overload

import casadi as ca
import numpy as np

from flexctrl.dynamics.model import Model


def state_names(model: Model) -> tuple[str, ...]:
    """The state's names: ``q1.., qf11.., dq1.., dqf11..`` (coordinates, then their rates).

    Parameters
    ----------
    model : Model
        Its ``coordinate_names`` are the first half.

    Returns
    -------
    tuple of str
        ``2 N`` names.
    """
    names = tuple(model.coordinate_names)
    return names + tuple("d" + n for n in names)


def input_names(model: Model) -> tuple[str, ...]:
    """The inputs' names ``tau1..taun`` (joint torques, N m), one per joint of ``model``.

    Parameters
    ----------
    model : Model
        The arm.

    Returns
    -------
    tuple of str
        One name per input.
    """
    return tuple(f"tau{i + 1}" for i in range(model.n_u))


@overload
def stiffness_matrix(model: Model, q: ca.SX) -> ca.SX | ca.DM: ...
@overload
def stiffness_matrix(model: Model, q: ca.MX) -> ca.MX | ca.DM: ...
@overload
def stiffness_matrix(model: Model, q: np.ndarray) -> np.ndarray: ...
def stiffness_matrix(
    model: Model, q: ca.SX | ca.MX | np.ndarray
) -> ca.SX | ca.MX | ca.DM | np.ndarray:
    """The stiffness ``K`` of ``model`` (N x N), constant or at ``q`` for scheduled modes.

    Parameters
    ----------
    model : Model
        Its ``functions["K"]`` (zero when it has none).
    q : casadi.SX, casadi.MX or ndarray
        Coordinates (rad, m).  Symbolic gives a CasADi matrix (an expression in ``q`` for
        scheduled modes, the constant ``DM`` otherwise), numeric an array.

    Returns
    -------
    casadi.SX, casadi.MX, casadi.DM or ndarray
        ``K`` in N/m, N m/rad.
    """
    fun = model.functions.get("K")
    if isinstance(q, (ca.SX, ca.MX)):
        if fun is None:
            return ca.DM.zeros(model.n_q, model.n_q)
        return fun(q) if fun.n_in() == 1 else fun()["K"]
    if fun is None:
        return np.zeros((model.n_q, model.n_q))
    return np.array(fun(q) if fun.n_in() == 1 else fun()["K"], dtype=float)


def torque_limits(model: Model, default: float = math.inf) -> np.ndarray:
    """Joint torque limits (N m), one per joint.

    Parameters
    ----------
    model : Model
        Read from its arm description (``spec.joints``), else ``info["torque_limits"]``.
    default : float
        The limit of every joint when the model states none, N m.

    Returns
    -------
    ndarray
        ``(n,)`` limits, N m.
    """
    joints = getattr(getattr(model, "spec", None), "joints", None)
    if joints is not None and len(joints) == model.n_u:
        return np.array([float(j.torque_limit) for j in joints])
    info = getattr(model, "info", {}) or {}
    if "torque_limits" in info:
        limits = np.asarray(info["torque_limits"], dtype=float)
        return np.broadcast_to(limits, (model.n_u,)).copy()
    return np.full(model.n_u, float(default))


def flexible_index(model: Model) -> np.ndarray:
    """Indices of the elastic coordinates in ``q`` (those after the ``n`` joint angles).

    Parameters
    ----------
    model : Model
        The arm.

    Returns
    -------
    numpy.ndarray
        Integer indices into ``q``.
    """
    return np.arange(model.n_u, model.n_q)
