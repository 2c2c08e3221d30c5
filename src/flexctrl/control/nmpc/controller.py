"""Nonlinear MPC in CasADi: multiple shooting with RK4, real-time iteration or full NLP.

The model predicted with is the design model or a reduction of it (``prediction_modes``;
:mod:`flexctrl.control.nmpc.prediction_model`: the joints and the slowest coupled modes at
the target, the estimate mapped with its fast modes removed); the shooting interval and its
sensitivities are :mod:`flexctrl.control.nmpc.interval`.

Variables are the scaled deviations of :mod:`flexctrl.control.mpc.controller` (same scales,
weights, DARE terminal cost, torque bounds and soft constraints), stage-wise::

    w = [z_0, v_0, s_0, z_1, v_1, s_1, ..., z_N]

Shooting map ``F``: ``substeps`` classical RK4 steps of the model's ``f(x, u)`` over one
sample (``f`` is called, not inlined, so generated code holds it once).

Real-time iteration (``mode = "rti"``, default): one Gauss-Newton SQP step per sample
(:mod:`flexctrl.control.nmpc.rti`).  One CasADi Function, ``linearize(Z, V, p) -> (F, A, B)``
mapped over the N intervals (compiled to C when ``compile``), gives the shooting ends and
their Jacobians along the previous (shifted) trajectory; a second assembles the QP (fixed
sparsity) and ``casadi.conic`` (HPIPM by default: Riccati-structured interior point) solves
it::

    min 1/2 w'Hw + g'w   s.t.  A_k z_k + B_k v_k - z_{k+1} = A_k zb_k + B_k vb_k - F(zb_k, vb_k)
                               soft rows on C z_{k+1}, torque bounds, z_0 = z(t)

The QP solution is the new trajectory (full step).  The sensitivities ``A_k, B_k`` may be
inexact (``sensitivities``, ``jacobian_every``, ``stages_per_jacobian``): the gaps use the
nonlinear ``F``, so the fixed points still satisfy the nonlinear shooting equations.  Per
sample the two calls go through buffers bound once, and the QP without its soft rows is
tried first (:mod:`flexctrl.control.nmpc.screened_qp`).

Generated code and the operating point.  The compiled ``linearize`` takes as its parameter
``p`` the operating point ``(x_op, u_op)``, the scales ``(S_x, S_u)`` and every numeric
constant of the model's ``f`` (:func:`~flexctrl.dynamics.parametric.constants_as_parameters`),
and the reference enters only ``g``, so its code depends only on the structure of the model's
expression graph, ``dt``, ``substeps``, the horizon and the sensitivities: a study over
targets, references and frozen-modes configurations of one payload compiles once (a payload
of 0 kg, or a value CasADi shares with its own constants, gives another structure).

Failures never raise out of :meth:`NMPCController.step`: QP data with NaN (or a non-finite
linearization), an exception of the QP solver and an unsuccessful or non-finite QP solution
are recorded as fall-backs (the shifted previous plan, then the LQR law about the reference)
with the reason, and the next sample linearizes along a fresh rollout from the measured
state instead of the trajectory that failed.

A moving reference (:mod:`flexctrl.control.reference_trajectory`) enters only the linear
cost, ``g = g0 - H w_ref`` with ``w_ref`` the scaled reference states and feed-forward
torques over the horizon: the stage costs penalize deviations from the reference while the
shooting constraints stay the nonlinear model (no reference consistency is assumed).

The soft rows use the output map linearized at the target; for the assumed-modes models
the link tip deflections are linear in the elastic coordinates, so the deflection
constraint is exact.

Full NLP (``mode = "full"``, :mod:`flexctrl.control.nmpc.nlp`): the same problem with the
nonlinear shooting constraints, solved by IPOPT, warm-started from the shifted previous
solution; an offline reference.  The first sample after :meth:`~NMPCController.reset` (and
the one after a failure) starts from the nonlinear rollout under the saturated LQR law
about the reference, ``v_k = clip(v_ref,k - K (z_k - z_ref,k))``, optionally improved by
``init_iter`` IPOPT iterations.
"""

from __future__ import annotations

import time

import numpy as np

from flexctrl.control.controller import Controller
from flexctrl.control.estimator import make_observer
from flexctrl.control.lqr import LinearPlant, build_sensors, linear_plant
from flexctrl.control.mpc.problem import ScaledProblem, scaled_problem
from flexctrl.control.mpc.qp_backends import Solution
from flexctrl.control.nmpc.casadi_functions import Layout, build_functions
from flexctrl.control.nmpc.interval import RK4_BOUND, auto_substeps, interval_functions
from flexctrl.control.nmpc.nlp import solve_nlp
from flexctrl.control.nmpc.prediction_model import Prediction, prediction_model
from flexctrl.control.nmpc.rti import BoundRTICalls, rti_step
from flexctrl.control.nmpc.screened_qp import ScreenedQP
from flexctrl.linear import OperatingPoint, equilibrium, torque_limits
from flexctrl.spec.controller_settings import NMPCSettings, SensorSettings


class NMPCController(Controller):
    """Nonlinear MPC (see the module docstring).

    Built by :func:`design_nmpc` (through :func:`flexctrl.design`).

    Parameters
    ----------
    settings : NMPCSettings
        Sample time, horizon, weights, sensitivities, prediction model, QP solver.
    plant : LinearPlant
        The design model's linearization at the target with the controller's sensors.
    limits : ndarray
        Torque limits per joint, N m.
    problem : ScaledProblem
        The scaled prediction model, weights and constraint rows.
    observer
        The state estimator (:mod:`flexctrl.control.estimator`).
    functions : dict
        The CasADi Functions of the real-time iteration (``prepare``, ``qp``, ``H``, ...).
    layout : Layout
        Where states, inputs and slacks sit in the QP's variables.
    substeps : int
        RK4 steps per sample of the prediction.
    compiled : bool
        Whether the linearization is a compiled library.
    prediction : Prediction, optional
        The prediction model (the design model or its truncation) and its state map.
    prediction_plant : LinearPlant, optional
        The prediction model's linearization (default ``plant``).
    design_model : Model, optional
        The model designed on (:class:`~flexctrl.control.controller.Controller`).
    """

    kind = "nmpc"

    def __init__(
        self,
        settings: NMPCSettings,
        plant: LinearPlant,
        limits: np.ndarray,
        problem: ScaledProblem,
        observer,
        functions: dict,
        layout: Layout,
        substeps: int,
        compiled: bool,
        prediction: Prediction | None = None,
        prediction_plant: LinearPlant | None = None,
        *,
        design_model=None,
    ):
        super().__init__(
            settings, plant.op, plant.sensors, limits, saturate=True, design_model=design_model
        )
        self.plant = plant
        #: the model predicted with and the selection ``x[keep]`` of the design state it sees
        self.prediction = prediction or Prediction(None, np.arange(plant.sys.A.shape[0]), False)
        self.prediction_plant = prediction_plant or plant
        self.keep = self.prediction.keep
        #: the prediction model's operating point (the design one unless the model is truncated)
        self.pred_op = self.prediction_plant.op
        #: the torque offset of the command, ``u = u_out + S_u v``: ``pred_op.u``, or ``op.u``
        #: with a modal map
        self.u_out = self.pred_op.u if self.prediction.state_map is None else plant.op.u
        self.problem = problem
        self.observer = observer
        self.functions = functions
        self.layout = layout
        self.substeps = substeps
        self.compiled = compiled
        self._w: np.ndarray | None = None
        self._plan: np.ndarray | None = None
        self._age = 0
        self.last: Solution | None = None
        self.timing: dict[str, list[float]] = {"linearize_qp": [], "qp": [], "total": []}
        self._reference_now = (np.zeros(problem.n), np.zeros(problem.m))
        self._w_ref: np.ndarray | None = None
        #: the last reference window's bytes and its ``(w_ref, g)`` (a settled reference repeats it)
        self._cost_window: tuple | None = None
        #: try the QP without its soft rows first and keep that answer when they hold (HPIPM;
        #: :mod:`flexctrl.control.nmpc.screened_qp`): the same optimum to the solver's tolerance
        self.screen = layout.ns > 0 and settings.qp_solver == "hpipm"
        self._rti_calls: BoundRTICalls | None = None

    def __getstate__(self) -> dict:
        # the buffers bound to this process's memory stay behind; made again on first use
        return {**self.__dict__, "_rti_calls": None}

    def _calls(self) -> BoundRTICalls:
        """The RTI's bound calls, made on first use (and after unpickling)."""
        if self._rti_calls is None:
            fn, pb = self.functions, self.problem
            screen = (
                ScreenedQP(
                    self.layout,
                    fn["Hnp"].toarray(),
                    fn["prepare"].sparsity_out(0),
                    pb.C,
                    pb.c_lo,
                    pb.c_hi,
                    self.settings.qp_warm_start,
                )
                if self.screen
                else None
            )
            self._rti_calls = BoundRTICalls(fn["prepare"], fn["qp"], fn["H"], screen)
        return self._rti_calls

    def _reset(self) -> None:
        self.observer.reset()
        self._w = None
        self._plan = None
        self._age = 0
        self.timing = {"linearize_qp": [], "qp": [], "total": []}

    def to_prediction(self, x: np.ndarray) -> np.ndarray:
        """The prediction model's state for the design model's state ``x``.

        ``x[keep]``, or the modal map of :mod:`flexctrl.control.nmpc.prediction_model`.
        """
        T = self.prediction.state_map
        return x[self.keep] if T is None else self.pred_op.x + T @ (x - self.op.x)

    def initial_guess(self, z0: np.ndarray, w_ref: np.ndarray | None = None) -> np.ndarray:
        """Nonlinear rollout from ``z0`` under the saturated LQR law, as ``w``.

        Parameters
        ----------
        z0 : ndarray
            Scaled initial state.
        w_ref : ndarray, optional
            Scaled reference over the horizon (as built by :meth:`cost_vector`); the law
            is then ``v_k = clip(v_ref,k - K (z_k - z_ref,k))``.  Default: regulation to
            the operating point.

        Returns
        -------
        ndarray
            ``w`` (may hold non-finite values when the rollout diverges; :meth:`_rti`
            checks).
        """
        lay = self.layout
        if w_ref is None:
            Zr, Vr = np.zeros((lay.n, lay.N)), np.zeros((lay.m, lay.N))
        else:
            Zr, Vr = w_ref[lay.z[:-1]].T, w_ref[lay.v].T
        Z, V = (np.array(a, dtype=float) for a in self.functions["rollout"](z0, Zr, Vr))
        w = np.zeros(lay.nw)
        w[lay.z[0]] = z0
        for k in range(lay.N):
            w[lay.z[k + 1]] = Z[:, k]
            w[lay.v[k]] = V[:, k]
        return w

    def cost_vector(self, t: float) -> np.ndarray:
        """Linear cost ``g = g0 - H w_ref`` of the reference over the horizon from ``t`` (s).

        ``w_ref`` holds the scaled reference states ``(x_ref,k - x_op) / S_x`` and inputs
        ``(u_ref,k - u_op) / S_u``, so the stage costs penalize deviations from the
        reference (:mod:`flexctrl.control.reference_trajectory`); ``g0`` for a reference at
        ``op``.

        Parameters
        ----------
        t : float
            The time of the horizon's first sample, s.

        Returns
        -------
        ndarray
            ``g`` (a copy).
        """
        lay, pb = self.layout, self.problem
        X, U, _ = self.reference.window(t, self.sample_time, lay.N + 1)
        window = (X.tobytes(), U.tobytes())
        if self._cost_window is not None and self._cost_window[0] == window:
            w_ref, g = self._cost_window[1]  # e.g. the reference has arrived
        else:
            # row by row, as the state is mapped in the loop (one matrix product would round
            # differently)
            w_ref = np.zeros(lay.nw)
            w_ref[lay.z.ravel()] = (
                (np.array([self.to_prediction(x) for x in X]) - self.pred_op.x) / pb.Sx
            ).ravel()
            w_ref[lay.v.ravel()] = ((U[: lay.N] - self.u_out) / pb.Su).ravel()
            g = self.functions["g0"] - self.functions["Hnp"] @ w_ref
            self._cost_window = (window, (w_ref, g))
        self._reference_now = (w_ref[lay.z[0]], w_ref[lay.v[0]])
        self._w_ref = w_ref
        return g.copy()

    def _bounds(self, z0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``w``: the torque bounds, slacks >= 0 and ``z_0`` fixed to ``z0`` (scaled)."""
        lbx, ubx = self.functions["lbx0"].copy(), self.functions["ubx0"].copy()
        lbx[self.layout.z[0]] = ubx[self.layout.z[0]] = z0
        return lbx, ubx

    def _nlp(
        self, z0: np.ndarray, w0: np.ndarray, max_iter: int, g: np.ndarray | None = None
    ) -> Solution:
        """The full NLP from ``w0`` (:func:`~flexctrl.control.nmpc.nlp.solve_nlp`)."""
        g = self.functions["g0"] if g is None else g
        return solve_nlp(self.functions, z0, w0, g, self._bounds(z0), max_iter, self.settings)

    def _rti(self, z0: np.ndarray, w0: np.ndarray, g: np.ndarray | None = None) -> Solution:
        """One RTI step along ``w0`` (:func:`~flexctrl.control.nmpc.rti.rti_step`)."""
        g = self.functions["g0"] if g is None else g
        return rti_step(self._calls(), z0, w0, g, self._bounds(z0), self.timing)

    def solve(self, x: np.ndarray, t: float = 0.0) -> Solution:
        """One NMPC solve (RTI step or NLP) for the design state ``x`` at ``t``.

        Updates the linearization's warm start, not the plan or the statistics.

        Parameters
        ----------
        x : ndarray
            The design model's state (absolute; rad, m, and their rates).
        t : float
            The time, s.

        Returns
        -------
        Solution
            The solver's answer in scaled variables.
        """
        z0 = (self.to_prediction(x) - self.pred_op.x) / self.problem.Sx
        g = self.cost_vector(t)
        if self._w is None:
            w0 = self.initial_guess(z0, self._w_ref)
            if self.settings.mode == "rti" and self.settings.init_iter > 0:
                init = self._nlp(z0, w0, self.settings.init_iter, g)
                if np.all(np.isfinite(init.w)):
                    w0 = init.w
        else:
            w0 = self._w[self.layout.shift]
            w0[self.layout.z[0]] = z0
        return (
            self._nlp(z0, w0, self.settings.max_iter, g)
            if self.settings.mode == "full"
            else self._rti(z0, w0, g)
        )

    def _step(self, t: float, y: np.ndarray) -> np.ndarray:
        start = time.perf_counter()
        return self._act(t, self.observer.estimate(y, self.u_previous), start)

    def _hold(self, t: float) -> np.ndarray | None:
        start = time.perf_counter()
        x = self.observer.predict(self.u_previous)
        return None if x is None else self._act(t, x, start)

    def _act(self, t: float, x: np.ndarray, start: float) -> np.ndarray:
        """One solve at ``t`` (s) from the state (estimate) ``x``; its first move or a fallback."""
        z0 = (self.to_prediction(x) - self.pred_op.x) / self.problem.Sx
        sol = self.solve(x, t)
        self.last = sol
        self.stats.iterations.append(sol.iterations)
        lay = self.layout
        if sol.ok:
            self.record("solved")
            self._w = sol.w
            self._plan = sol.w[lay.v]
            self._age = 0
            if lay.ns:
                self.stats.slack_max = max(
                    self.stats.slack_max, float(np.max(sol.w[lay.s])) * self.problem.h
                )
            v = self._plan[0]
        else:
            self._age += 1
            # the linearization trajectory led to a failed QP: start the next sample from a
            # fresh rollout of the nonlinear model from the measured state
            self._w = None
            if self._plan is not None and self._age < lay.N:
                v = self._plan[self._age]
                used = "shift"
            else:
                z_ref, v_ref = self._reference_now
                v = np.clip(
                    v_ref - self.problem.K @ (z0 - z_ref), self.problem.v_lo, self.problem.v_hi
                )
                used = "lqr"
                self._w = None
                self._plan = None
            self.fallback(t, sol.status, used)
        self.timing["total"].append(time.perf_counter() - start)
        return self.u_out + self.problem.Su * v


def design_nmpc(model, op: OperatingPoint, settings: NMPCSettings) -> NMPCController:
    """Build the nonlinear MPC regulating ``model`` to ``op`` (Functions and solvers, once).

    The compiled linearization is shared (disk cache) by every ``op`` and every model with
    the same expression-graph structure; ``functions["build"]`` reports the compile time (s),
    whether the library came from the cache and how many model constants were lifted.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model.
    op : flexctrl.linear.OperatingPoint
        The target equilibrium.
    settings : NMPCSettings
        The controller's settings.

    Returns
    -------
    NMPCController
    """
    limits = torque_limits(model)
    sensors = build_sensors(model, settings.sensors, op)
    plant = linear_plant(model, op, sensors, settings.sample_time)
    prediction = prediction_model(
        model,
        settings.prediction_modes,
        basis=settings.prediction_basis,
        mapping=settings.prediction_map,
        mass=np.asarray(model.functions["M"](op.x[: model.n_q]), dtype=float),
        a_lin=np.asarray(plant.sys.A, dtype=float),
    )
    pm = prediction.model
    if prediction.reduced and pm is not None:  # its own equilibrium at the target joints, all
        # of its state measured (a reduced prediction always carries its model)
        pop = equilibrium(pm, op.joints)
        pplant = linear_plant(
            pm, pop, build_sensors(pm, SensorSettings(), pop), settings.sample_time
        )
    else:
        pm, pplant = model, plant
    problem = scaled_problem(pm, pplant, settings, limits)
    substeps = settings.substeps or auto_substeps(pplant)
    # the reduced basis's values merge by coincidence at some configurations: lift per use, so one
    # compiled library serves every configuration of a payload (as for the design model)
    functions, layout, compiled = build_functions(
        pm, pplant, settings, problem, substeps, prediction.reduced
    )
    observer = make_observer(model, op, sensors, plant.sys.A, plant.sysd, settings.estimator)
    return NMPCController(
        settings,
        plant,
        limits,
        problem,
        observer,
        functions,
        layout,
        substeps,
        compiled,
        prediction,
        pplant,
        design_model=model,
    )


__all__ = ["NMPCController", "design_nmpc", "interval_functions", "auto_substeps", "RK4_BOUND"]
