"""The linear estimate of a closed loop's plant rungs, for the estimate-first walk.

:func:`linear_closed_rung` runs the scene's closed loop with the plant at a rung
replaced by its linearisation: the rung's model linearised at its static equilibrium
at the target (``dx' = A dx + B du``; gravity-free moves of joint 1 on a planar arm
are invariant in ``q1``, so the target's linearisation holds along the whole
reference path, velocity terms apart), advanced over the scene's grid step ``g`` by

* ``rk4``: ``g / h`` steps of RK4 at the rung's own step ``h`` applied to the linear
  system (its exact one-step map ``P(hA) = I + hA + ... + (hA)^4 / 24``), so the
  estimate carries the integrator's error as the nonlinear run does; or
* ``exact``: the zero-order-hold exponential (no integrator error).

The controller is the real one (designed as for the nonlinear runs, its saturation
and constraints kept), called on the linear plant's measurements; controllers with a
sampled law run in one CasADi call (:mod:`flexctrl.loop.compiled`), others sample by
sample.  The tip is the model's nonlinear tip map of the linear states on the grid.
A run costs a fraction of the nonlinear loop; it is an estimate to pick the rung to
certify, never a certificate.
"""

from __future__ import annotations

import dataclasses
import math
import time

import casadi as ca
import numpy as np
from scipy.linalg import expm

from flexctrl.fidelity.ladder import RunRecord
from flexctrl.linear import Linearizer, equilibrium
from flexctrl.loop.run_state import LoopRun
from flexctrl.loop.sampled import run_samples, tip_positions
from flexctrl.scenes.cache import SceneCache, read_only
from flexctrl.scenes.loop_setup import build_loop
from flexctrl.spec.fidelity import parse_fidelity

#: How a linear rung is advanced over the grid step: RK4 at the rung's step, or exactly.
LINEAR_STEPS = ("rk4", "exact")


def grid_maps(
    A: np.ndarray, B: np.ndarray, grid: float, h: float | None
) -> tuple[np.ndarray, np.ndarray]:
    """``(Phi, Gamma)`` of ``dx_{j+1} = Phi dx_j + Gamma du`` over one grid step (s), ``du`` held.

    ``h`` None: the exact zero-order hold.  Otherwise ``grid / h`` (a whole number) RK4
    steps of ``h`` on ``dx' = A dx + B du``: one step is ``dx + h T(hA) (A dx + B du)``
    with ``T(Z) = I + Z/2 + Z^2/6 + Z^3/24``.

    >>> import numpy as np
    >>> A, B = np.array([[0.0, 1.0], [-4.0, -0.1]]), np.array([[0.0], [1.0]])
    >>> P1, G1 = grid_maps(A, B, 1e-3, None)
    >>> P2, G2 = grid_maps(A, B, 1e-3, 1e-4)
    >>> bool(np.allclose(P1, P2, atol=1e-12) and np.allclose(G1, G2, atol=1e-12))
    True
    """
    n, m = B.shape
    if h is None:
        M = np.zeros((n + m, n + m))
        M[:n, :n], M[:n, n:] = A * grid, B * grid
        E = expm(M)
        return E[:n, :n], E[:n, n:]
    steps = int(round(grid / h))
    Z = h * A
    T = np.eye(n) + Z / 2 + Z @ Z / 6 + Z @ Z @ Z / 24
    P1, G1 = np.eye(n) + h * T @ A, h * T @ B
    P, G = np.eye(n), np.zeros((n, m))
    for _ in range(steps):
        P, G = P1 @ P, P1 @ G + G1
    return P, G


def linear_advance(
    x_op: np.ndarray, u_op: np.ndarray, Phi: np.ndarray, Gamma: np.ndarray, substeps: int
) -> ca.Function:
    """``advance(x, u, dt) -> X`` (n_x, substeps): the linear plant's states over a held sample."""
    n = x_op.size
    P, G = [np.eye(n)], [np.zeros_like(Gamma)]
    for _ in range(substeps):
        P.append(Phi @ P[-1])
        G.append(Phi @ G[-1] + Gamma)
    Ps, Gs = np.vstack(P[1:]), np.vstack(G[1:])
    x, u, dt = ca.MX.sym("x", n), ca.MX.sym("u", u_op.size), ca.MX.sym("dt")
    stacked = ca.mtimes(ca.DM(Ps), x - ca.DM(x_op)) + ca.mtimes(ca.DM(Gs), u - ca.DM(u_op))
    X = ca.reshape(stacked, n, substeps) + ca.repmat(ca.DM(x_op), 1, substeps)
    return ca.Function("linear_advance", [x, u, dt], [X], ["x", "u", "dt"], ["X"])


def linear_closed_rung(
    scene,
    fidelity: str,
    h: float | None,
    *,
    controller=None,
    overrides=(),
    cache: SceneCache | None = None,
) -> RunRecord:
    """The scene's closed loop on the linearised plant at ``fidelity``, on the scene's grid.

    The method is the module docstring's.

    Parameters
    ----------
    scene : ClosedLoopScene
        With its design model pinned (``controller_fidelity``).
    fidelity : str
        The plant rung.
    h : float or None
        The RK4 step (s) the rung is run with (dividing the grid step ``scene.plant.dt``),
        or None for the exact zero-order hold.

    Returns
    -------
    RunRecord
        ``integrator`` is ``"linear-rk4"`` or ``"linear-exact"``, ``dt`` the step ``h``
        (the grid step when exact); ``wall_time_s`` the whole estimate (linearising,
        discretising and the loop).
    """
    cache = SceneCache() if cache is None else cache
    start = time.perf_counter()
    grid = float(scene.plant.dt)
    setup = loop_at(scene, fidelity, controller, overrides, cache)
    plant, ctrl = setup.plant, setup.controller
    build = time.perf_counter() - start
    op = equilibrium(plant, scene.target_q)
    # linearised with the loop's sensors: the loop's verdict reuses the linearisation
    A, B = Linearizer(plant, setup.sensors).matrices(op)[:2]
    Phi, Gamma = grid_maps(A, B, grid, h)
    Ts = ctrl.sample_time
    substeps = int(round(Ts / grid))
    advance = linear_advance(
        np.asarray(op.x, dtype=float), np.asarray(op.u, dtype=float), Phi, Gamma, substeps
    )
    run = LoopRun(
        plant,
        ctrl,
        setup.sensors,
        advance,
        setup.x0,
        dt=grid,
        substeps=substeps,
        stride=1,
        n_samples=int(math.ceil(scene.plant.duration / Ts - 1e-9)),
    )
    run_samples(run)
    t, X, U = run.kept()
    tip = tip_positions(plant, X, scene.plant.solver.get("compile"))
    times, tip, torque = read_only(t, tip, U.copy())
    diverged = None if run.divergence is None else float(run.divergence["time"])
    return RunRecord(
        fidelity=str(fidelity),
        integrator="linear-exact" if h is None else "linear-rk4",
        dt=grid if h is None else float(h),
        omega_max=float(plant.omega_max),
        wall_time_s=time.perf_counter() - start - build,
        build_time_s=build,
        time=times,
        tip=tip,
        diverged_at=diverged,
        torque=torque,
    )


def loop_at(scene, fidelity: str, controller, overrides, cache: SceneCache):
    """The scene's loop with the plant at ``fidelity`` on the scene's grid step.

    Models and design come from ``cache``.
    """
    plant_scene = dataclasses.replace(scene.plant, fidelity=parse_fidelity(fidelity))
    return build_loop(dataclasses.replace(scene, plant=plant_scene), controller, overrides, cache)
