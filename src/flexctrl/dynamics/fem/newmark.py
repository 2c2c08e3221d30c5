"""Newmark integration of a :class:`~flexctrl.dynamics.model.Model` (Pan et al. 1990, Sec. 4).

Finite-element models are stiff: their highest locked-joint frequency grows like
``N^2`` (about 0.5e6 rad/s for the three-link arm at 16 elements per link, from the
axial elements), so an explicit integrator needs ``dt < 2.8 / omega_max``.  The
trapezoidal Newmark rule (``alpha = 0.25, delta = 0.5``) is unconditionally stable
and conserves the energy of linear undamped systems; its step is chosen for
accuracy of the modes that matter, not for stability.  This module wraps a
model as a :class:`~flexctrl.dynamics.fem.newmark_dae.DAEProblem`::

    M(q) qdd + Phi_q^T lam = B tau(t) - c(q, qd) - g(q) - K q - D qd

with optional locked joints (``Phi = q_r - q_lock``, the joints clamped by
multipliers; used for locked-joint free vibration) and integrates it with
:func:`flexctrl.dynamics.fem.newmark_dae.simulate`.

Newton tangents (all converge to the same step: the residual is exact):
``tangent="exact"`` differentiates ``c`` and ``g`` (CasADi AD; costly for large
models); ``"potential"`` (default) uses the Hessian of the potential energy
(``d(g + K q)/dq``, which holds the geometric stiffness of large deflections) and
``-D``, leaving out the velocity terms; ``"stiffness"`` uses ``-K`` and ``-D`` only
(cheapest, but Newton can fail at large deflections).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Literal

import casadi as ca
import numpy as np

from flexctrl.dynamics.fem.newmark_dae import DAEProblem, DAEResult, simulate

Torque = Callable[[float], np.ndarray]


class DenseEvaluator:
    """A CasADi Function evaluated into preallocated numpy arrays (no DM conversions).

    Outputs are densified; matrices come back column-major, so only symmetric
    ones (or their transposes) may be read directly -- ``transpose`` fixes the rest.
    """

    def __init__(self, fun: ca.Function):
        ins = [ca.SX.sym(f"i{k}", fun.size_in(k)) for k in range(fun.n_in())]
        called = fun(*ins)
        outs = called if isinstance(called, (list, tuple)) else [called]
        self.fun = ca.Function(f"{fun.name()}_dense", ins, [ca.densify(o) for o in outs])
        self.args = [np.zeros(int(np.prod(fun.size_in(k)))) for k in range(fun.n_in())]
        self.res = [np.zeros(fun.size_out(k)[::-1]) for k in range(fun.n_out())]
        self.buffer, self.evaluate = self.fun.buffer()
        # the stubs are wrong twice: casadi's give set_arg C's (pointer, size), numpy's give
        # ndarray __buffer__ on Python 3.12+ only
        for k, arr in enumerate(self.args):
            view = memoryview(arr)  # type: ignore[arg-type]  # numpy stubs: see above
            self.buffer.set_arg(k, view)  # type: ignore[call-arg]  # casadi stubs: see above
        for k, arr in enumerate(self.res):
            view = memoryview(arr)  # type: ignore[arg-type]  # numpy stubs: see above
            self.buffer.set_res(k, view)  # type: ignore[call-arg]  # casadi stubs: see above

    def __call__(self, *args: np.ndarray) -> list[np.ndarray]:
        for dst, src in zip(self.args, args):
            dst[:] = np.ravel(src)
        self.evaluate()
        return [r.T.copy() for r in self.res]


def model_dae_problem(
    model,
    torque: Torque | None = None,
    *,
    locked: Sequence[float] | None = None,
    tangent: Literal["potential", "stiffness", "exact"] = "potential",
) -> DAEProblem:
    """The model's equations of motion as a :class:`DAEProblem`.

    Parameters
    ----------
    model
        A :class:`~flexctrl.dynamics.model.Model` (any family).
    torque
        ``tau(t)`` in N m, shape ``(n_joints,)``; None for no torque.
    locked
        Joint angles (rad) at which the joints are clamped by constraints, or None.
    tangent
        ``"potential"``, ``"stiffness"`` or ``"exact"`` Newton tangents (module docstring).
    """
    if tangent not in ("potential", "stiffness", "exact"):
        raise ValueError(
            f"tangent {tangent!r} is not allowed; allowed: 'potential', 'stiffness', 'exact'"
        )
    n_q, n_u = model.n_q, model.n_u
    q, qd = ca.SX.sym("q", n_q), ca.SX.sym("qd", n_q)
    fn = model.functions
    K = fn["K"]()["K"] if fn["K"].n_in() == 0 else fn["K"](q)
    D = fn["D"]()["D"] if fn["D"].n_in() == 0 else fn["D"](q)
    inner = fn["c"](q, qd) + fn["g"](q) + ca.mtimes(K, q) + ca.mtimes(D, qd)
    if tangent == "exact":
        d_q, d_qd = ca.jacobian(inner, q), ca.jacobian(inner, qd)
    elif tangent == "potential":
        d_q, d_qd = ca.jacobian(fn["g"](q) + ca.mtimes(K, q), q), D + ca.SX.zeros(n_q, n_q)
    else:
        d_q, d_qd = K + ca.SX.zeros(n_q, n_q), D + ca.SX.zeros(n_q, n_q)
    mass = DenseEvaluator(ca.Function("M", [q], [fn["M"](q)]))
    internal = DenseEvaluator(ca.Function("internal", [q, qd], [inner]))
    tangents = DenseEvaluator(ca.Function("tangents", [q, qd], [d_q, d_qd]))
    B = np.zeros(n_q)
    cache: dict[str, tuple] = {}

    def force(qv: np.ndarray, qdv: np.ndarray, t: float) -> np.ndarray:
        out = -internal(qv, qdv)[0].ravel()
        if torque is not None:
            B[:n_u] = np.asarray(torque(t), dtype=float).reshape(n_u)
            out = out + B
        return out

    def tangent_pair(qv: np.ndarray, qdv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = (qv.tobytes(), qdv.tobytes())
        if cache.get("key") != key:
            a, b = tangents(qv, qdv)
            cache["key"], cache["value"] = key, (-a, -b)
        return cache["value"]

    n_c = 0 if locked is None else n_u
    lock = np.zeros(0) if locked is None else np.asarray(locked, dtype=float).reshape(n_u)
    Pq = np.zeros((n_c, n_q))
    Pq[np.arange(n_c), np.arange(n_c)] = 1.0
    zc, zcq = np.zeros(n_c), np.zeros((n_c, n_q))
    return DAEProblem(
        n_q=n_q,
        n_c=n_c,
        mass=lambda qv, t: mass(qv)[0],
        force=force,
        phi=lambda qv, t: qv[:n_c] - lock,
        phi_q=lambda qv, t: Pq,
        phi_t=lambda qv, t: zc,
        h=lambda qv, qdv, t: zc,
        force_q=lambda qv, qdv, t: tangent_pair(qv, qdv)[0],
        force_qd=lambda qv, qdv, t: tangent_pair(qv, qdv)[1],
        h_q=lambda qv, qdv, t: zcq,
        h_qd=lambda qv, qdv, t: zcq,
    )


def simulate_model_newmark(
    model,
    x0,
    duration: float,
    dt: float,
    *,
    torque: Torque | None = None,
    locked: Sequence[float] | None = None,
    alpha: float = 0.25,
    delta: float = 0.5,
    gamma: float = 5.0,
    beta: float = 5.0,
    tangent: Literal["potential", "stiffness", "exact"] = "potential",
    newton_tol: float = 1e-10,
    max_iterations: int = 30,
) -> DAEResult:
    """Integrate ``model`` from ``x0 = (q, qd)`` with Newmark (see module docstring).

    Parameters
    ----------
    x0
        Initial state, shape ``(2 n_q,)``.
    duration, dt
        Simulated time and step (s).
    torque, locked, tangent
        See :func:`model_dae_problem`.
    alpha, delta
        Newmark parameters (0.25, 0.5: trapezoidal rule).
    gamma, beta
        Baumgarte parameters for the locked-joint constraints (1/s).
    """
    x0 = np.asarray(x0, dtype=float).ravel()
    n = model.n_q
    problem = model_dae_problem(model, torque, locked=locked, tangent=tangent)
    return simulate(
        problem,
        x0[:n],
        x0[n:],
        duration,
        dt,
        gamma=gamma,
        beta=beta,
        alpha=alpha,
        delta=delta,
        newton_tol=newton_tol,
        max_iterations=max_iterations,
        max_violation=np.inf,
    )
