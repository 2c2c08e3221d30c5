"""The linear verdict: the sampled closed loop's spectral radius on the plant's own linearisation.

A controller that is linear about its reference at rest gives its law as ``linear_law(q)``
(PD, shaped PD, LQR and LQG, gain-scheduled LQR at ``q``, the unconstrained linear MPC),
in deviations from the reference::

    xi_k = E xi_{k-1} + F dy_k + G du_{k-1}        (its memory: an estimate, a filter state)
    du_k = H xi_k + J dy_k

The plant is linearised at its own static equilibrium at the target (its own payload,
pose and fidelity) and discretised by zero-order hold at the controller's sample time,
``dx_{k+1} = A dx_k + B du_k``, its sensors (the controller's kinds built on the plant;
a full-state controller on another rung reads the projected state) linearised there,
``dy_k = C dx_k + D du_{k-1}`` (a tip accelerometer feels the torque held over the sample
that just ended).  With ``s_k = (dx_k, xi_{k-1}, du_{k-1})``::

    xi_k  = F C dx + E xi + (F D + G) du_prev
    du_k  = H xi_k + J (C dx + D du_prev)
    dx'   = A dx + B du_k

and the verdict is the spectral radius of that map: below 1 the target is locally
asymptotically stable under the unsaturated law, a check of the simulated verdict that
shares no code with the run.  Controllers without a linear law (NMPC) give None.
"""

from __future__ import annotations

import control
import numpy as np

from flexctrl.errors import SpecError
from flexctrl.linear import Linearizer, discretize, equilibrium


def closed_loop_matrix(Ad, Bd, C, D, law) -> np.ndarray:
    """The map ``s_k -> s_{k+1}`` of the module docstring, ``s = (dx, xi, du_prev)``."""
    E, F, G, H, J = (np.asarray(m, dtype=float) for m in law)
    n, m, p = Ad.shape[0], E.shape[0], Bd.shape[1]
    xi = np.hstack([F @ C, E, F @ D + G])
    du = H @ xi + J @ np.hstack([C, np.zeros((C.shape[0], m)), D])
    dx = np.hstack([Ad, np.zeros((n, m)), np.zeros((n, p))]) + Bd @ du
    return np.vstack([dx, xi, du])


def linear_closed_loop_radius(plant, controller, target_q, sensors=None) -> float | None:
    """Spectral radius of the sampled loop of ``controller`` on ``plant`` about ``target_q``.

    The loop is the module docstring's map.

    Parameters
    ----------
    plant : Model
        The controlled arm.
    controller : Controller
        With a ``linear_law(q)`` method; otherwise the answer is None.
    target_q : sequence of float
        Joint angles of the target, rad.
    sensors : Sensors, optional
        The controller's sensor kinds built on the plant, as the loop reads them
        (:func:`flexctrl.loop.mismatch.plant_sensors`); default the controller's own
        (plant and design model the same).

    Returns
    -------
    float or None
    """
    law = getattr(controller, "linear_law", None)
    if law is None:
        return None
    sensors = controller.sensors if sensors is None else sensors
    if sensors.n_y != controller.sensors.n_y:
        raise SpecError(
            f"the plant's sensors give {sensors.n_y} values, the controller reads "
            f"{controller.sensors.n_y}",
            key="sensors",
        )
    q = np.asarray(target_q, dtype=float)
    op = equilibrium(plant, tuple(q))
    A, B, C, D = Linearizer(plant, sensors).matrices(op)
    sysd = discretize(control.ss(A, B, np.eye(A.shape[0]), 0), controller.sample_time)
    Ad, Bd = np.asarray(sysd.A, dtype=float), np.asarray(sysd.B, dtype=float)
    matrix = closed_loop_matrix(
        Ad, Bd, np.asarray(C, dtype=float), np.asarray(D, dtype=float), law(q)
    )
    return float(np.max(np.abs(np.linalg.eigvals(matrix))))
