"""The payload-aware linear MPC: the payload bank's estimate picks the prediction model.

Built by :func:`design_mpc_payload` from an MPC file with a ``[payload]`` table.  Every
sample the bank (:mod:`flexctrl.control.payload.bank`) learns from the measurement, the
design runs at the grid payload at or below the estimate's light side (as
:mod:`flexctrl.control.payload.lqr_payload`), and that grid point's MPC (its prediction
model, DARE terminal cost, soft deflection rows and QP workspace, built from the grid's
linearisation when the grid is built) solves from the bank's state estimate of the same
payload, along the reference built on that payload's model.  A switch starts the new QP
cold (no plan of another model to shift) and carries the torque held.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from flexctrl.control.mpc.controller import MPCController
from flexctrl.control.mpc.problem import scaled_problem
from flexctrl.control.mpc.qp import condensed_qp, sparse_qp
from flexctrl.control.mpc.qp_backends import make_backend
from flexctrl.control.payload.lqr_payload import PayloadAware
from flexctrl.linear import OperatingPoint, torque_limits


class BankState:
    """The bank's filter ``i`` as an inner MPC's observer (the bank is updated by the owner)."""

    def __init__(self, owner, i: int):
        self.owner, self.i = owner, i
        self._filter = owner.grid.designs[i].observer

    def reset(self) -> None:
        """The bank resets with its owner."""

    def estimate(self, y: np.ndarray, u_previous: np.ndarray) -> np.ndarray:
        """The bank's state estimate of payload ``i`` (absolute)."""
        return self.owner.bank.state(self.i)

    def linear_form(self, n_y: int, n_u: int):
        """The filter's ``(E, F, G)`` (:meth:`KalmanEstimator.linear_form`)."""
        return self._filter.linear_form(n_y, n_u)


class PayloadMPCController(PayloadAware):
    """The payload-aware MPC (module docstring); built by :func:`design_mpc_payload`.

    Parameters
    ----------
    settings : MPCSettings
        The recipe with its ``payload`` table.
    model : flexctrl.dynamics.model.Model
        The design model (its payload is replaced by the grid's).
    op : OperatingPoint
        The target without a reference.
    certify : bool
        Compute the grid certificate when a grid is built and warn on a failing cell.
    """

    kind = "mpc"

    def __init__(self, settings, model, op: OperatingPoint, *, certify: bool = True):
        super().__init__(settings, model, op, certify=certify)
        self._inner: dict[tuple, MPCController] = {}

    def _mpc(self, i: int) -> MPCController:
        """The MPC of grid payload ``i`` at the current pose, tracking its reference, kept."""
        key = (self._pose(), i)
        inner = self._inner.get(key)
        if inner is None:
            design = self.grid.designs[i]
            plain = dataclasses.replace(self.settings, payload=None)
            limits = torque_limits(design.model)
            problem = scaled_problem(design.model, design.plant, plain, limits)
            if plain.formulation == "sparse":
                qp = sparse_qp(problem, soft_on_next=plain.backend == "hpipm")
            else:
                qp = condensed_qp(problem, plain.blocks, plain.constraint_stride)
            inner = MPCController(
                plain,
                design.plant,
                limits,
                problem,
                qp,
                make_backend(qp, plain),
                BankState(self, i),
                design_model=design.model,
            )
            inner.set_reference(self._reference(i))
            inner.stats = self.stats
            self._inner[key] = inner
        return inner

    def _reference_changed(self) -> None:
        """The grid, the references and every grid point's QP at the new target, built now."""
        super()._reference_changed()
        for i in range(len(self.grid.designs)):
            self._mpc(i).set_reference(self._reference(i))

    def _reset(self) -> None:
        super()._reset()
        for inner in self._inner.values():
            inner.reset()
            inner.stats = self.stats

    def _law(self, t: float, i: int, switched: bool) -> np.ndarray:
        inner = self._mpc(i)
        if switched:
            inner.reset()
            inner.stats = self.stats
        inner.u_previous = self.u_previous
        return inner._step(t, np.zeros(0))

    def _step(self, t: float, y: np.ndarray) -> np.ndarray:
        before = self.index
        i = self._learn(t, y)
        return self._law(t, i, i != before)

    def _hold(self, t: float) -> np.ndarray:
        """Torques without a measurement: the bank predicts, the estimate is not updated."""
        return self._law(t, self._coast(t), False)

    def linear_law(self, q_joints) -> tuple[np.ndarray, ...]:
        """The unconstrained law of the grid MPC in use (:meth:`MPCController.linear_law`)."""
        E, F, G, _H, J = self.grid.designs[self.index].law
        return E, F, G, -self._mpc(self.index).unconstrained_gain(), J


def design_mpc_payload(model, op: OperatingPoint, settings) -> PayloadMPCController:
    """Build the payload-aware MPC of ``settings`` (an :class:`MPCSettings` with ``payload``).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model; its payload is replaced by every grid payload.
    op : OperatingPoint
        The target without a reference.
    settings : MPCSettings
        Horizon, weights, constraints, QP solver, sensors, estimator noise and ``payload``.

    Returns
    -------
    PayloadMPCController
    """
    return PayloadMPCController(settings, model, op)


__all__ = ["PayloadMPCController", "design_mpc_payload", "BankState"]
