"""The linear verdict: the closed loop's spectral radius on the plant's own linearisation."""

from __future__ import annotations

import numpy as np

from flexctrl.errors import SpecError
from flexctrl.loop.mismatch import state_projection


def linear_closed_loop_radius(plant, controller, target_q) -> float | None:
    """Spectral radius of the *plant's* ZOH linearisation at the target closed with the controller's gain.

    ``max |eig(A_d - B_d K)|`` with ``A_d, B_d`` of the plant (its own payload) at the
    target equilibrium and ``K`` the controller's state-feedback gain there (LQR, gain-
    scheduled LQR, the unconstrained MPC), times the :func:`state_projection` when the
    plant is another assumed-modes rung than the design model: below 1 the target is locally asymptotically
    stable under the unsaturated law, an independent check of the simulated verdict.
    ``None`` for controllers without a full-state gain or of another state dimension.
    """
    import control

    from flexctrl.linear import Linearizer, discretize, equilibrium

    if not getattr(controller.sensors, "full_state", False):
        return None
    if controller.sensors.n_y == plant.n_x:
        P = np.eye(plant.n_x)
    else:
        try:
            P = state_projection(plant, controller.sensors.names)
        except SpecError:
            return None
    op = equilibrium(plant, np.asarray(target_q, dtype=float))
    if hasattr(controller, "gain"):
        K = controller.gain(P @ op.x)
    elif hasattr(controller, "K"):
        K = controller.K
    else:
        return None
    A, B, _C, _D = Linearizer(plant, ("joints",)).matrices(op)
    sysd = discretize(control.ss(A, B, np.eye(A.shape[0]), 0), controller.sample_time)
    Ad, Bd = np.asarray(sysd.A, dtype=float), np.asarray(sysd.B, dtype=float)
    return float(np.max(np.abs(np.linalg.eigvals(Ad - Bd @ np.asarray(K, dtype=float) @ P))))

