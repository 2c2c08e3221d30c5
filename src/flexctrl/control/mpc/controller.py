"""Linear MPC on the discretised linearisation at the design point: one QP per sample, built once.

Problem (deviations from the reference over the horizon, scaled, see below)::

    min  1/2 sum_{k<N} (z_k' Q z_k + v_k' R v_k) + 1/2 z_N' P z_N + sum_k (l1 s_k + 1/2 l2 s_k^2)
    s.t. z_0 = z(t),   z_{k+1} = A z_k + B v_k,
         u_min - u_ref,k <= v_k <= u_max - u_ref,k                      (hard: torque limits)
         lo - c_op - C r_k+1 - s_k <= C z_{k+1} <= hi - c_op - C r_k+1 + s_k,  s_k >= 0
                                 (soft: deflection or tip error; the bounds of ``constraints``)
         Ts du_lo <= u_k - u_k-1 <= Ts du_hi         (hard: torque rates, u_-1 the last torque)

The bounds of ``settings.constraints`` (:mod:`flexctrl.spec.mpc_constraints`: joint angles and
rates, link deflections, the tip position) are rows of ``C`` with their values ``c_op`` at the
target, each scaled by its own magnitude (the Bryson joint and joint-rate magnitudes, the soft
limit's scale for lengths); a hard one has its slack held at zero.

with ``z_k = x_k - x_ref(t + k Ts)``, ``v_k = u_k - u_ref(t + k Ts)`` and ``r_k = x_ref(t + k Ts) -
x_op`` (:mod:`flexctrl.control.reference_trajectory`: the joint path, its quasi-static deflection
and the feed-forward torque; with no reference ``x_ref = x_op``, ``u_ref = u_op``).  The prediction
``x_k+1 - x_ref,k+1 = A (x_k - x_ref,k) + B (u_k - u_ref,k)`` uses the Jacobians of the design point
along the reference: exact for a reference that is a trajectory of the linear model, and without
steady-state offset at a target equilibrium away from the design point (the target's holding torque
is ``u_ref``). Only the bounds depend on the reference, so between samples only vectors change.

``P`` is the DARE solution (``terminal = "dare"``), so without active constraints the
first move is the LQR move ``-K z(t)``.  The slack makes the QP feasible for any
initial state; ``l1`` is an exact penalty (constraints hold whenever they can, for
``l1`` above the multipliers), ``l2`` keeps the Hessian positive definite.

Formulations
    ``sparse``: variables ``[z_0, v_0, s_0, z_1, v_1, s_1, ..., z_N]`` (stage-wise, the
    order HPIPM wants), dynamics as equality rows; between samples only the bounds of
    ``z_0`` change (OSQP ``update(l=, u=)``), so the sparsity and the KKT factorisation
    never change.  ``condensed``: states eliminated, variables ``[v, s]``, dense Hessian;
    ``z(t)`` enters the linear cost and the bounds of the soft rows.

Scaling
    ``z = S_x^-1 dx``, ``v = S_u^-1 du`` with ``S_u`` the torque magnitudes of the
    weights.  ``scaling = "auto"``: ``S_x`` is the largest excursion of each state in
    LQR closed-loop responses from each joint displaced by the acceptable joint error
    (floored at 1 % of the largest of its kind), so states are O(1) in normal
    operation; ``"bryson"``: ``S_x`` = the acceptable magnitudes (``Q = I``); ``"none"``.
    Soft rows are divided by their limit (or the modal weight when the limit is 0).

Backends
    ``osqp`` (the ``osqp`` package, warm-started with the shifted previous primal and
    dual solution or the previous one), or ``hpipm``/``daqp``/``qpoases`` through
    ``casadi.conic`` (HPIPM needs the sparse stage-wise form; its soft rows act on
    ``A z_k + B v_k``, which is the same constraint on ``z_{k+1}``).

Minimum-time arrival
    With ``[arrival] kind = "minimum_time"`` (condensed) the controller plans, at its first
    sample, the earliest time the arm can be held inside a band and asks every later
    prediction to be there from then on (:mod:`flexctrl.control.mpc.arrival_search`).

Fallback
    When the QP is not solved (OSQP ``max_iter``/``time_limit`` reached, infeasible,
    or a conic failure), ``fallback = "shift"`` applies the previous plan shifted by
    the number of samples since it was computed and, once that runs out, the LQR move;
    ``"lqr"`` the LQR move; ``"hold"`` the previous torque.  Every fallback is recorded in
    :attr:`Controller.stats`.
"""

from __future__ import annotations

import time

import numpy as np

from flexctrl.control.controller import Controller
from flexctrl.control.estimator import make_observer
from flexctrl.control.lqr import LinearPlant, build_sensors, linear_plant
from flexctrl.control.mpc.arrival_search import shortest_arrival, stage_times
from flexctrl.control.mpc.problem import ScaledProblem, scaled_problem
from flexctrl.control.mpc.qp import QP, condensed_qp, sparse_qp
from flexctrl.control.mpc.qp_backends import Solution, make_backend
from flexctrl.linear import OperatingPoint, torque_limits
from flexctrl.spec.mpc_settings import MPCSettings


class MPCController(Controller):
    """Linear MPC (see the module docstring).

    Built by :func:`design_mpc` (through :func:`flexctrl.design`).

    Parameters
    ----------
    settings : MPCSettings
        Sample time, horizon, weights, constraints, QP backend, sensors, estimator.
    plant : LinearPlant
        The linearization at the design point with the controller's sensors.
    limits : ndarray
        Torque limits per joint, N m.
    problem : ScaledProblem
        The scaled prediction model, weights and constraint rows.
    qp : QP
        The quadratic programme, built once.
    backend
        Its solver (:mod:`flexctrl.control.mpc.qp_backends`).
    observer
        The state estimator (:mod:`flexctrl.control.estimator`).
    design_model : Model, optional
        The model designed on (:class:`~flexctrl.control.controller.Controller`).
    """

    kind = "mpc"

    def __init__(
        self,
        settings: MPCSettings,
        plant: LinearPlant,
        limits: np.ndarray,
        problem: ScaledProblem,
        qp: QP,
        backend,
        observer,
        *,
        design_model=None,
    ):
        super().__init__(
            settings, plant.op, plant.sensors, limits, saturate=True, design_model=design_model
        )
        self.plant = plant
        self.problem = problem
        self.qp = qp
        self.backend = backend
        self.observer = observer
        #: The state the weights act on, in order (``Q``'s rows): joints, elastic coordinates,
        #: rates.
        self.state_names = tuple(plant.sys.state_labels)
        self._w: np.ndarray | None = None  # last solution
        self._plan: np.ndarray | None = None  # (N, m) scaled moves of the last solution
        self._plan_u: np.ndarray | None = None  # (N, m) planned torques, N m
        self._age = 0
        self._arrival: float | None = (
            None  # absolute time (s) from which the predictions must be in the band
        )
        self.last: Solution | None = None

    @property
    def K(self) -> np.ndarray:
        """LQR gain in physical units (``du = -K dx``)."""
        pb = self.problem
        return pb.Su[:, None] * pb.K / pb.Sx[None, :]

    def linear_law(self, q_joints) -> tuple[np.ndarray, ...]:
        """The unconstrained law on the estimate, as :meth:`LQRController.linear_law`.

        With the DARE terminal cost and free moves it is the LQR move ``-K dx``; with move
        blocking or a stage terminal cost it is the first move of the unconstrained,
        condensed QP, ``v_0 = -(H^-1 F z)_0`` (slacks at zero), in physical units.
        """
        E, F, G = self.observer.linear_form(self.sensors.n_y, self.n_u)
        return E, F, G, -self.unconstrained_gain(), np.zeros((self.n_u, self.sensors.n_y))

    def unconstrained_gain(self) -> np.ndarray:
        """``K`` of the first move ``du = -K dx`` with no constraint active (N m per state unit)."""
        if self.settings.terminal == "dare" and not self.settings.blocks:
            return self.K
        pb = self.problem
        qp = condensed_qp(pb, self.settings.blocks, 1)
        nv, Gz = qp.n_moves, qp.Gz
        if Gz is None:  # the condensed QP's cost always depends on the initial state
            raise ValueError("the condensed QP has no state-dependent cost")
        H = qp.H.toarray()[:nv, :nv]
        Kz = np.linalg.solve(H, Gz[:nv])[qp.first_move]  # v_0 = -Kz z
        return pb.Su[:, None] * Kz / pb.Sx[None, :]

    def _reset(self) -> None:
        self.observer.reset()
        self.backend.reset()
        self._w = None
        self._plan = None
        self._plan_u = None
        self._age = 0
        self._arrival = None

    def _reference_changed(self) -> None:
        self._arrival = None

    def arrival_release(
        self, t: float, z: np.ndarray, dv: np.ndarray, dc: np.ndarray
    ) -> np.ndarray | None:
        """Which constrained stages have their arrival rows released at ``t`` (s).

        The first call after a reset or a new reference plans the arrival time
        (:func:`~flexctrl.control.mpc.arrival_search.shortest_arrival` plus the margin) and
        records it in :attr:`stats` (``arrival_time_s``, ``arrival_feasible``,
        ``arrival_search_ms``).

        Parameters
        ----------
        t : float
            The time, s.
        z : ndarray
            The scaled initial state deviation.
        dv, dc : ndarray
            The reference shifts of the input and soft-row bounds (:meth:`reference_shifts`).

        Returns
        -------
        ndarray of bool or None
            One per constrained stage; None without arrival rows.
        """
        arrival = self.settings.arrival
        if not arrival.enabled:
            return None
        times = stage_times(self.qp, t, self.sample_time)
        if self._arrival is None:
            start = time.perf_counter()
            first = shortest_arrival(self.qp, z, dv, dc)
            self._arrival = float(times[-1] if first is None else times[first] + arrival.margin)
            self.stats.notes.update(
                {
                    "arrival_time_s": self._arrival,
                    "arrival_feasible": first is not None,
                    "arrival_search_ms": 1e3 * (time.perf_counter() - start),
                }
            )
        return times < self._arrival - 1e-9 * max(1.0, abs(self._arrival))

    def plan(self) -> np.ndarray | None:
        """Planned torques (N m) of the last solved QP, shape (N, n_u)."""
        return None if self._plan_u is None else self._plan_u.copy()

    def reference_shifts(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Scaled reference over the horizon from ``t`` (s).

        ``r_k = (x_ref,k - x_op) / S_x``; ``dv``, ``dc`` shift the input and soft-row bounds.

        Returns
        -------
        tuple of ndarray
            ``r`` (N+1, n), ``u_ref`` (N, m) in N m, ``dv`` (N, m) and ``dc`` (N, ns).
        """
        pb = self.problem
        X, U, _ = self.reference.window(t, self.sample_time, pb.horizon + 1)
        r = (X - self.op.x) / pb.Sx
        dv = (U[:-1] - self.op.u) / pb.Su
        dc = r[1:] @ pb.C.T if pb.ns else np.zeros((pb.horizon, 0))
        return r, U[:-1], dv, dc

    def solve(self, x: np.ndarray, t: float = 0.0) -> Solution:
        """Solve the QP for the state ``x`` at time ``t`` and return the raw :class:`Solution`.

        For inspection: the plan and the statistics are not updated (OSQP's internal
        warm start is).

        Parameters
        ----------
        x : ndarray
            The state (absolute: rad, modal coordinates and their rates).
        t : float
            The time, s.

        Returns
        -------
        Solution
            In scaled variables.
        """
        r, u_ref, dv, dc = self.reference_shifts(t)
        z = (x - self.op.x) / self.problem.Sx - r[0]
        warm = self._w if self.settings.warm_start != "none" else None
        release = self.arrival_release(t, z, dv, dc)
        return self.backend.solve(z, warm, dv, dc, release, self.rate_shifts(u_ref))

    def rate_shifts(self, u_ref: np.ndarray) -> np.ndarray | None:
        """The torque-rate rows' bound shifts for the reference torques ``u_ref`` (N, m), N m.

        Row ``k`` is the reference's change into stage ``k`` (from the last torque applied,
        :attr:`u_previous`, for ``k = 0``), scaled; None without torque-rate bounds.
        """
        pb = self.problem
        if not pb.rate_joints.size:
            return None
        before = np.vstack([self.u_previous[None, :], u_ref[:-1]])
        return ((u_ref - before) / pb.Su)[:, pb.rate_joints]

    def export_c(self, out, *, replay=None, qp_eps: float | None = None):
        """The MPC in C (:meth:`Controller.export_c`; :mod:`flexctrl.control.cexport.mpc_dense`)."""
        from flexctrl.control.cexport.mpc_dense import export_mpc

        return export_mpc(self, out, replay, qp_eps)

    def _step(self, t: float, y: np.ndarray) -> np.ndarray:
        return self._act(t, self.observer.estimate(y, self.u_previous))

    def _hold(self, t: float) -> np.ndarray | None:
        x = self.observer.predict(self.u_previous)
        return None if x is None else self._act(t, x)

    def _act(self, t: float, x: np.ndarray) -> np.ndarray:
        """Solve the QP at ``t`` (s) from the state estimate ``x``: its first move or a fallback."""
        r, u_ref, dv, dc = self.reference_shifts(t)
        z = (x - self.op.x) / self.problem.Sx - r[0]
        release = self.arrival_release(t, z, dv, dc)
        sol = self.backend.solve(
            z,
            self._w if self.settings.warm_start != "none" else None,
            dv,
            dc,
            release,
            self.rate_shifts(u_ref),
        )
        self.last = sol
        self.stats.iterations.append(sol.iterations)
        if sol.ok:
            self.record(sol.status or "solved")
            self._w = sol.w
            self._plan = sol.w[self.qp.moves]
            self._plan_u = u_ref + self._plan * self.problem.Su
            self._age = 0
            if self.qp.slack.size:
                self.stats.slack_max = max(
                    self.stats.slack_max, self.problem.slack_violation(sol.w[self.qp.slack])
                )
            return self._plan_u[0].copy()
        self._age += 1
        fb = self.settings.fallback
        if fb == "shift" and self._plan_u is not None and self._age < self.problem.horizon:
            u = self._plan_u[self._age].copy()
            used = "shift"
        elif fb == "hold":
            self.fallback(t, sol.status, "hold")
            return self.u_previous.copy()
        else:
            u = u_ref[0] + self.problem.Su * (-self.problem.K @ z)
            used = "lqr"
        self.fallback(t, sol.status, used)
        if self._w is not None:
            self._w = self._w[self.qp.shift_w]  # keep warm starts moving with time
        return u


def design_mpc(model, op: OperatingPoint, settings: MPCSettings) -> MPCController:
    """Build the linear MPC regulating ``model`` to ``op`` (its QP and solver workspace, once).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model.
    op : OperatingPoint
        The target equilibrium.
    settings : MPCSettings
        The MPC's settings.

    Returns
    -------
    MPCController
    """
    limits = torque_limits(model)
    sensors = build_sensors(model, settings.sensors, op)
    plant = linear_plant(model, op, sensors, settings.sample_time)
    problem = scaled_problem(model, plant, settings, limits)
    if settings.formulation == "sparse":
        qp = sparse_qp(problem, soft_on_next=settings.backend == "hpipm")
    else:
        qp = condensed_qp(problem, settings.blocks, settings.constraint_stride)
    backend = make_backend(qp, settings)
    observer = make_observer(model, op, sensors, plant.sys.A, plant.sysd, settings.estimator)
    return MPCController(
        settings, plant, limits, problem, qp, backend, observer, design_model=model
    )


__all__ = ["MPCController", "design_mpc"]
