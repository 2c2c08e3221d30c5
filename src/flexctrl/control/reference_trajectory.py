"""Reference trajectories: a joint path and the state and feed-forward torque that go with it.

:class:`~flexctrl.spec.reference.JointReference` (plain data) is the joint path ``q_ref(t)`` from
``q_start`` to ``q_target``
(rad), either a step at ``t_start`` or a quintic over ``move_time`` (s)::

    q_ref(t) = q_start + (q_target - q_start) s(tau),   tau = clip((t - t_start) / move_time, 0, 1)
    s(tau)   = 10 tau^3 - 15 tau^4 + 6 tau^5

the minimum-jerk point-to-point path: zero velocity and acceleration at both ends,
peak velocity ``1.875 dq / T`` at mid-move, peak acceleration ``5.774 dq / T^2`` at
``tau = 0.211`` and ``0.789``.

:class:`ReferenceTrajectory` puts the path on a model (the controller's design model)
and gives, at any time, the reference state ``x_ref = (q_ref, q_f*, qd_ref, qd_f*)`` and
the feed-forward joint torque ``u_ref``.  The elastic coordinates follow one of

``"quasi_static"`` (default)
    the deflection the links need to carry the path's accelerations: ``q_f*`` solves
    the elastic rows of the equations of motion with the elastic accelerations set to
    zero, ``[M(q*) (qdd_ref, 0) + c(q*, (qd_ref, 0)) + g(q*) + K q*]_f = 0`` (Newton, AD
    Jacobians), and ``qd_f*`` is its exact time derivative (implicit-function theorem
    with the path's jerk).  Then ``u_ref = [M(q*) (qdd_ref, 0) + c + g + K q*]_r`` is the
    torque for which the model, at ``x_ref``, accelerates the joints exactly along the
    path with no elastic acceleration (the forces include the damping of the elastic
    rates ``qd_f*``).  Why this one: an LQR or MPC regulating to a zero (static) deflection
    fights the bending every acceleration must cause, which is itself a torque input that
    excites the modes (``docs/guide/design-a-controller.md`` compares the two on a move).
``"static"``
    the static equilibrium deflection at ``q_ref(t)`` (gravity only: zero in a
    horizontal plane); ``u_ref`` is the same rigid feed-forward evaluated there.

``u_static`` is the holding torque at ``q_ref(t)`` (the static equilibrium), for PD's
gravity compensation.  With a step the reference is the target equilibrium from
``t_start`` on, so a controller regulating to it behaves exactly as one regulating
to the target.

Controllers read the reference on their sample grid; :meth:`ReferenceTrajectory.window`
returns ``count`` samples from ``t`` (MPC horizons) from a table computed once per
sample time.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from flexctrl.dynamics.model import derived
from flexctrl.dynamics.parametric import parametric
from flexctrl.errors import SolverError, SpecError
from flexctrl.linear import OperatingPoint, stiffness_matrix
from flexctrl.sim.compile import QUICK_FLAGS, compile_for
from flexctrl.spec.reference import DEFLECTIONS, JointReference, JointSequence, Move, MoveSequence


def _damping_matrix(model, q):
    fun = model.functions.get("D")
    if fun is None:
        return ca.SX.zeros(model.n_q, model.n_q)
    return fun(q) if fun.n_in() == 1 else fun()["D"]


def path_functions(model, compile: bool | None = False) -> dict[str, ca.Function]:
    """The reference's CasADi Functions of ``(qr, qdr, qddr, qf, qdf, qddf)``.

    ``rj -> (r_f, J_qf)``, ``all -> (r_f, J_qf, J_qr, J_qdr, J_qddr)`` and
    ``tau -> (tau, tau_static)`` (see the module docstring).  Built once per model and
    ``compile`` (kept with the model, :func:`~flexctrl.dynamics.model.derived`).

    Compiled, the generalized forces are rebuilt with their numeric constants as an input,
    one per use (:func:`flexctrl.dynamics.parametric.constants_as_parameters`),
    differentiated with the constants symbolic and compiled as ONE Function of all seven
    outputs, named by the sizes alone: every configuration and payload of one model shape
    shares one library.  The compiled Function is kept with the lifted forces
    (:func:`flexctrl.sim.compile.compile_for`), so a new configuration pays the lift alone,
    not the Jacobians, the cache key or the load.  The three Functions bind the model's
    constants to it.  When the constants cannot be lifted or nothing compiles, the virtual
    machine's Functions are returned.  Compiled values differ from the virtual machine's in
    the last digits (fused multiply-adds, no constant folding).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model.
    compile : bool or None
        ``False``: SX Functions evaluated in CasADi's virtual machine (where there is no
        compiler); ``None``: compiled unless compilation is switched off (as
        :func:`flexctrl.sim.compile.compile_function`); ``True``: compiled.

    Returns
    -------
    dict
        ``{"rj", "all", "tau"}``.
    """
    return derived(model, ("reference_functions", compile), lambda: _path_functions(model, compile))


def _path_functions(model, compile: bool | None) -> dict[str, ca.Function]:
    n, N = model.n_u, model.n_q
    qr, qdr, qddr = (ca.SX.sym(name, n) for name in ("qr", "qdr", "qddr"))
    qf, qdf, qddf = ca.SX.sym("qf", N - n), ca.SX.sym("qdf", N - n), ca.SX.sym("qddf", N - n)
    args = [qr, qdr, qddr, qf, qdf, qddf]
    names = ["qr", "qdr", "qddr", "qf", "qdf", "qddf"]
    q = ca.vertcat(qr, qf)
    qd = ca.vertcat(qdr, qdf)
    qdd = ca.vertcat(qddr, qddf)
    static = model.functions["g"](q) + ca.mtimes(stiffness_matrix(model, q), q)
    force = (
        ca.mtimes(model.functions["M"](q), qdd)
        + model.functions["c"](q, qd)
        + static
        + ca.mtimes(_damping_matrix(model, q), qd)
    )
    if compile is False:
        return _functions(args, names, _outputs(force, static, qr, qdr, qddr, qf, n))
    forces = ca.Function("reference_forces", args, [force, static], names, ["force", "static"])
    fp, constants = parametric(model, "reference_forces", lambda: forces, per_use=True)
    if constants.size == 0:
        return path_functions(model, False)

    def one() -> ca.Function:
        c = ca.SX.sym("c", constants.size)
        lifted_force, lifted_static = fp(*args, c)
        outs = _outputs(lifted_force, lifted_static, qr, qdr, qddr, qf, n)
        return ca.Function(
            f"reference_p_{n}_{N}_{constants.size}",
            [*args, c],
            outs,
            [*names, "c"],
            ["r", "J_qf", "J_qr", "J_qdr", "J_qddr", "tau", "tau_static"],
        )

    # kept with the lifted forces: a later configuration of the model shape skips the Jacobians and
    # the load
    compiled = compile_for(fp, "reference", one, enabled=compile, flags=QUICK_FLAGS)
    if not compiled.compiled:
        return path_functions(model, False)
    mx = [ca.MX.sym(name, a.sparsity()) for name, a in zip(names, args)]
    return _functions(mx, names, compiled.function.call([*mx, ca.DM(constants)]))


def _outputs(force, static, qr, qdr, qddr, qf, n: int) -> list:
    """``[r_f, J_qf, J_qr, J_qdr, J_qddr, tau, tau_static]`` of the generalized forces."""
    r = force[n:]
    return [
        r,
        ca.jacobian(r, qf),
        ca.jacobian(r, qr),
        ca.jacobian(r, qdr),
        ca.jacobian(r, qddr),
        force[:n],
        static[:n],
    ]


def _functions(args, names, outs) -> dict[str, ca.Function]:
    """``rj``, ``all`` and ``tau`` (:func:`path_functions`) of :func:`_outputs` at ``args``."""
    return {
        "rj": ca.Function("reference_rj", args, outs[:2], names, ["r", "J_qf"]),
        "all": ca.Function(
            "reference_all", args, outs[:5], names, ["r", "J_qf", "J_qr", "J_qdr", "J_qddr"]
        ),
        "tau": ca.Function("reference_tau", args, outs[5:], names, ["tau", "tau_static"]),
    }


class ReferenceTrajectory:
    """State and feed-forward of a :class:`JointReference` on ``model`` (see the module docstring).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The controller's design model.
    path : JointReference
        The joint path (rad, s).
    deflection : {"quasi_static", "static"}
        How the elastic coordinates follow the path (module docstring).
    tol : float
        Newton tolerance on the elastic coordinates (relative to ``1 + |q_f|``).
    max_iter : int
        Newton passes before :class:`~flexctrl.errors.SolverError`.
    compile : bool or None
        How the equations of motion are evaluated in the Newton iteration and the
        feed-forward (:func:`path_functions`): ``False`` (default) CasADi's virtual
        machine; ``None`` a compiled library unless compilation is switched off
        (``FLEXCTRL_NO_COMPILE``), ``True`` compiled.  Compiled tables differ from the
        virtual machine's in the last digits.
    """

    def __init__(
        self,
        model,
        path: JointReference | JointSequence,
        deflection: str = "quasi_static",
        *,
        tol: float = 1e-10,
        max_iter: int = 30,
        compile: bool | None = False,
    ):
        if deflection not in DEFLECTIONS:
            raise SpecError(
                f"value {deflection!r} is not allowed; allowed: "
                f"{', '.join(map(repr, DEFLECTIONS))}",
                key="deflection",
            )
        if len(path.q_target) != model.n_u:
            raise SpecError(
                f"the reference has {len(path.q_target)} joint angles; expected {model.n_u}",
                key="target",
            )
        self.model = model
        self.path = path
        self.deflection = deflection
        self.tol, self.max_iter = tol, max_iter
        self.n_u, self.n_q = model.n_u, model.n_q
        self.compile = compile
        #: the tables computed so far, by ``(sample time, elastic)``
        self._tables: dict[tuple[float, bool], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    @property
    def t_arrive(self) -> float:
        """End of the move, s."""
        return self.path.t_arrive

    @property
    def _fun(self) -> dict[str, ca.Function]:
        return path_functions(self.model, self.compile)

    def _elastic(
        self, derivs, moving: bool, elastic: bool, qddf: np.ndarray, qf: np.ndarray, qdf: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(q_f, qd_f)`` at the path points ``derivs = (q, qd, qdd, qddd)`` (each T x n).

        For the given elastic accelerations ``qddf``, from the start ``(qf, qdf)``.
        """
        q, qd, qdd, qddd = derivs
        T, n = q.shape
        nf = self.n_q - n
        if not nf:
            return qf, qdf
        rj, full = (self._fun[name].map(T) for name in ("rj", "all"))

        def blocks(value, cols):  # mapped (rows, cols * T) -> (T, rows, cols)
            return np.array(value, dtype=float).T.reshape(T, cols, -1).transpose(0, 2, 1)

        zero = np.zeros_like(qd)
        mq, mqdd, mqddd = (qd, qdd, qddd) if moving else (zero, zero, zero)
        for _ in range(self.max_iter):
            # one Newton step on q_f and one implicit-function update of qd_f per pass (the elastic
            # rates enter the Coriolis and damping forces, so q_f and qd_f are a joint fixed point)
            out = (full if elastic else rj)(q.T, mq.T, mqdd.T, qf.T, qdf.T, qddf.T)
            J_qf = blocks(out[1], nf)
            step = np.linalg.solve(J_qf, np.array(out[0], dtype=float).T[:, :, None])[:, :, 0]
            qf = qf - step
            change = 0.0
            if elastic:
                J_qr, J_qdr, J_qddr = (blocks(v, n) for v in out[2:5])
                rate = J_qr @ qd[:, :, None] + J_qdr @ mqdd[:, :, None] + J_qddr @ mqddd[:, :, None]
                qdf_new = -np.linalg.solve(J_qf, rate)[:, :, 0]
                change = float(np.max(np.abs(qdf_new - qdf))) / (
                    1.0 + float(np.max(np.abs(qdf_new)))
                )
                qdf = qdf_new
            if (
                max(float(np.max(np.abs(step))) / (1.0 + float(np.max(np.abs(qf)))), change)
                <= self.tol
            ):
                return qf, qdf
        raise SolverError(
            f"reference: Newton on the elastic coordinates did not converge in {self.max_iter} "
            f"passes (last step {np.max(np.abs(step)):.3g})"
        )

    def evaluate(self, t, *, elastic: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(x_ref (T, 2N), u_ref (T, n), u_static (T, n))`` at the times ``t`` (s).

        With ``elastic=False`` the elastic coordinates are the static deflection at
        ``q_ref`` and their rates zero whatever :attr:`deflection` says (a cheaper rigid
        feed-forward).

        Raises
        ------
        SolverError
            If Newton on the elastic coordinates does not converge.
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        T, n, N = t.size, self.n_u, self.n_q
        nf = N - n
        derivs = self.path.derivatives(t, order=3)
        q, qd, qdd, _qddd = derivs
        moving = self.deflection == "quasi_static" and elastic
        qddf = np.zeros((T, nf))
        qf, qdf = self._elastic(derivs, moving, elastic, qddf, np.zeros((T, nf)), np.zeros((T, nf)))
        # the elastic accelerations stay zero: correcting them with d^2 q_f*/dt^2 is a series in
        # the path's frequency over the first locked mode's, which does not settle in one step
        # when the two are only a few times apart
        ftau = self._fun["tau"].map(T)
        out = ftau(q.T, qd.T, qdd.T, qf.T, qdf.T, qddf.T)
        tau, tau_static = np.array(out[0], dtype=float).T, np.array(out[1], dtype=float).T
        if (
            moving and nf
        ):  # the holding torque belongs to the static deflection, not the quasi-static one
            zero = np.zeros((T, nf))
            qf_static, _ = self._elastic(derivs, False, False, zero, qf, zero)
            tau_static = np.array(
                ftau(q.T, 0 * qd.T, 0 * qdd.T, qf_static.T, zero.T, zero.T)[1], dtype=float
            ).T
        return np.hstack([q, qf, qd, qdf]), tau, tau_static

    def _table(self, Ts: float, elastic: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        key = (float(Ts), elastic)
        table = self._tables.get(key)
        if table is None:
            count = int(math.ceil(self.t_arrive / Ts - 1e-9)) + 2
            table = self.evaluate(np.arange(count) * Ts, elastic=elastic)
            self._tables[key] = table
        return table

    def window(
        self, t: float, Ts: float, count: int, *, elastic: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``count`` samples ``t, t + Ts, ...``: ``(x_ref (count, 2N), u_ref (count, n), u_static
        (count, n))``.

        On the grid ``k Ts`` the values come from a table computed once (up to the end
        of the move; constant after it); elsewhere they are evaluated.
        """
        k0 = int(round(t / Ts))
        if k0 < 0 or abs(t - k0 * Ts) > 1e-9 * max(1.0, abs(t)):
            return self.evaluate(t + Ts * np.arange(count), elastic=elastic)
        X, U, Us = self._table(Ts, elastic)
        idx = np.minimum(k0 + np.arange(count), X.shape[0] - 1)
        return X[idx], U[idx], Us[idx]

    def at(
        self, t: float, Ts: float, *, elastic: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(x_ref, u_ref, u_static)`` at ``t`` (s).

        From the table of sample time ``Ts`` (s) when ``t`` is on its grid.
        """
        X, U, Us = self.window(t, Ts, 1, elastic=elastic)
        return X[0], U[0], Us[0]


class HoldReference:
    """The constant reference of a controller regulating to its operating point (the default).

    Parameters
    ----------
    op : OperatingPoint
        The operating point.
    """

    deflection = "static"

    def __init__(self, op: OperatingPoint):
        self.op = op
        self.path = JointReference(tuple(op.joints), tuple(op.joints))

    @property
    def t_arrive(self) -> float:
        """End of the move, s: none, so 0."""
        return 0.0

    def window(
        self, t: float, Ts: float, count: int, *, elastic: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``count`` rows of the operating point (as :meth:`ReferenceTrajectory.window`)."""
        return (
            np.tile(self.op.x, (count, 1)),
            np.tile(self.op.u, (count, 1)),
            np.tile(self.op.u, (count, 1)),
        )

    def at(
        self, t: float, Ts: float, *, elastic: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(x_op, u_op, u_op)`` (as :meth:`ReferenceTrajectory.at`)."""
        return self.op.x, self.op.u, self.op.u


def reference_from_move(model, move: Move | MoveSequence) -> ReferenceTrajectory:
    """The reference a controller designed on ``model`` tracks along ``move``.

    The joint path of ``move`` with its elastic part (``move.deflection``) on ``model``: what
    :func:`flexctrl.closed_loop` and :meth:`Controller.set_reference
    <flexctrl.control.controller.Controller.set_reference>` give the controller.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The controller's design model.
    move : Move or MoveSequence
        The joint move (rad, s).

    Returns
    -------
    ReferenceTrajectory
    """
    return ReferenceTrajectory(model, move.joint_reference(), move.deflection)


__all__ = ["ReferenceTrajectory", "HoldReference", "reference_from_move"]
