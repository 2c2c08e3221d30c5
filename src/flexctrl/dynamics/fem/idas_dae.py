"""The prescribed-motion sliding links integrated by IDAS, a variable-order BDF (Gear-type) code.

Pan, Scott & Ulsoy (1990, Sec. 4) write: "Computer runs showed the current method [Newmark with
Baumgarte stabilisation] to be more efficient than existing codes based on Gear's algorithm."  To
test that, :func:`simulate_idas` hands the same equations to SUNDIALS IDAS (CasADi's ``idas``
integrator) in the index-1 form the paper starts from (Eqs 44, 47)::

    x = (q, qd),  z = (qdd, lam):   x' = (qd, qdd),
    0 = M qdd + Phi_q^T lam - f(q, t),   0 = Phi_q qdd - h + 2 gamma Phidot + beta^2 Phi

(``gamma = beta = 0``: the plain index-1 DAE, as a Gear-type code integrates it; otherwise with
Eq 49's Baumgarte terms).  The model is any :class:`~flexctrl.dynamics.fem.rp_arm.RPArmModel` --
the rotating arm, or the beam over supports (housing fixed, driven at H; it *is* the sliding
beam, a test of ``rp_arm`` shows).  Everything is symbolic in ``t``: the rigid motion of Eq 57,
``K + K_g(t) - theta'^2 M`` and the loads (:meth:`FrameLink.terms` with CasADi arguments), and the
constraint rows ``w^(o_k)(x_k(t))`` whose support points slide from element to element
(:func:`symbolic_point_row`: the Hermite cubic of the element containing ``x``, chosen by
``if_else``).  ``Phi_q``, ``Phi_t`` and ``h`` (Eq 47) follow by automatic differentiation.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexctrl.beam.elements import hermite_shape
from flexctrl.dynamics.fem.rp_arm import RPArmModel
from flexctrl.errors import SolverError

Array = NDArray[np.float64]


def _hermite_coefficients(le: float) -> Array:
    """``C[d, k, i]``: the ``d``-th derivative of shape function ``i`` is ``sum_k C[d, k, i] z^k``.

    Exact: the cubic through four samples of :func:`~flexctrl.beam.elements.hermite_shape`.
    """
    zs = le * np.array([0.0, 1 / 3, 2 / 3, 1.0])
    C0 = np.linalg.solve(np.vander(zs, 4, increasing=True), hermite_shape(zs, le, 0))
    C = np.zeros((4, 4, 4))
    C[0] = C0
    for d in range(1, 4):
        C[d, :-1] = C[d - 1, 1:] * np.arange(1, 4)[:, None]
    return C


def symbolic_point_row(x: Any, order: int, n_elements: int, length: float) -> Any:
    """CasADi row (1 x ``2 (N + 1)``) with ``w^(order)(x) = row @ q`` at a symbolic point ``x``.

    ``x`` is a material point (m) on a uniform mesh of Hermite elements; an interior node
    belongs to the element on its right.

    Parameters
    ----------
    x : casadi.SX
        The material point, m.
    order : int
        Derivative of ``w`` along the link, 0..3.
    n_elements : int
        Elements of the mesh.
    length : float
        Link length, m.

    Returns
    -------
    casadi.SX
        The row (units of ``w^(order)`` per unit of ``q``).
    """
    import casadi as ca  # lazily: the numpy models never need CasADi

    le = length / n_elements
    C = _hermite_coefficients(le)[order]
    j = ca.fmin(ca.fmax(ca.floor(x / le), 0), n_elements - 1)
    row = ca.SX.zeros(1, 2 * (n_elements + 1))
    for e in range(n_elements):
        zeta = x - e * le
        powers = ca.horzcat(1, zeta, zeta**2, zeta**3)
        row[0, 2 * e : 2 * e + 4] += ca.if_else(
            j == e, ca.mtimes(powers, ca.DM(C)), ca.DM.zeros(1, 4)
        )
    return row


@dataclass(frozen=True)
class IdasResult:
    """An IDAS run on the output grid ``t`` (s).

    Nodal values ``q`` and rates ``qd``, the tracked-end deflection ``tip_y`` (m), constraint
    violations ``phi_violation`` (m) and ``phidot_violation`` (m/s) evaluated independently from
    the numpy rows, ``wall_time`` (s) of the integration and the solver statistics ``stats``
    (steps, residual evaluations).
    """

    t: Array
    q: Array
    qd: Array
    tip_y: Array
    phi_violation: Array
    phidot_violation: Array
    wall_time: float
    rtol: float
    atol: float
    max_order: int
    stats: dict


def simulate_idas(
    model: RPArmModel,
    q0: Array,
    t_end: float,
    grid_dt: float,
    *,
    rtol: float = 1e-6,
    atol: float | None = None,
    gamma: float = 0.0,
    beta: float = 0.0,
    tracked_dof: int | None = None,
    max_num_steps: int = 20000,
    suppress_algebraic: bool = True,
    max_order: int = 5,
) -> IdasResult:
    """Integrate ``model`` from ``q0`` at rest with IDAS, output every ``grid_dt`` s to ``t_end``.

    Parameters
    ----------
    rtol, atol
        IDAS tolerances (``atol`` default ``1e-3 rtol``, in m, rad and their rates).
    gamma, beta
        Baumgarte terms (1/s) in the acceleration constraint; 0 gives the plain index-1 DAE.
    tracked_dof
        Nodal dof reported as ``tip_y`` (default the tip H).
    max_num_steps
        IDAS's step limit per output interval.
    suppress_algebraic
        Leave ``qdd`` and ``lam`` out of the local error test (they jump where a support crosses a
        node: ``h`` holds ``w''`` rows); with them in, IDAS stalls at the first crossing.
    max_order
        Highest BDF order (5: IDAS's default; 1-2 are A-stable, which matters for the undamped
        high-frequency element modes).

    Raises
    ------
    SolverError
        IDAS failed (names the tolerance and the message).
    """
    import casadi as ca  # lazily: the numpy models never need CasADi

    n = model.ndof
    n_out = int(round(t_end / grid_dt))
    grid = grid_dt * np.arange(1, n_out + 1)
    atol = 1e-3 * rtol if atol is None else atol
    opts = {
        "reltol": rtol,
        "abstol": atol,
        "max_num_steps": max_num_steps,
        "calc_ic": True,
        "suppress_algebraic": suppress_algebraic,
        "max_order": max_order,
    }
    F = ca.integrator("F", "idas", _index1_dae(model, gamma, beta), 0.0, list(grid), opts)
    x0 = np.concatenate([q0, np.zeros(n)])
    z0 = _consistent_start(model, q0)
    start = time.perf_counter()
    try:
        out = F(x0=x0, z0=z0)
    except RuntimeError as exc:
        raise SolverError(
            f"IDAS failed (rtol = {rtol:g}, atol = {atol:g}): {str(exc).splitlines()[-1]}"
        ) from exc
    wall = time.perf_counter() - start
    X = np.concatenate([x0[:, None], np.asarray(out["xf"])], axis=1).T
    stats = {k: v for k, v in F.stats().items() if isinstance(v, (int, float, bool))}
    return _result(model, X, np.concatenate([[0.0], grid]), tracked_dof, wall, stats, opts)


def _result(
    model: RPArmModel,
    X: Array,
    tt: Array,
    tracked_dof: int | None,
    wall: float,
    stats: dict,
    opts: dict[str, Any],
) -> IdasResult:
    """The states ``X`` at ``tt`` as an :class:`IdasResult`, the violations from the numpy rows."""
    n, prob = model.ndof, model.problem()
    Q, QD = X[:, :n], X[:, n:]
    vp = np.array([np.abs(prob.phi(a, s)).max() for a, s in zip(Q, tt)])
    vv = np.array(
        [np.abs(prob.phi_q(a, s) @ b + prob.phi_t(a, s)).max() for a, b, s in zip(Q, QD, tt)]
    )
    dof = model.tip if tracked_dof is None else tracked_dof
    return IdasResult(
        t=tt,
        q=Q,
        qd=QD,
        tip_y=Q[:, dof],
        phi_violation=vp,
        phidot_violation=vv,
        wall_time=wall,
        rtol=opts["reltol"],
        atol=opts["abstol"],
        max_order=opts["max_order"],
        stats=stats,
    )


def _index1_dae(model: RPArmModel, gamma: float, beta: float) -> dict[str, Any]:
    """The semi-explicit index-1 DAE of ``model`` for ``casadi.integrator`` (module docstring)."""
    import casadi as ca  # lazily: the numpy models never need CasADi

    n, rows, link = model.ndof, model.rows, model.link
    t = ca.SX.sym("t")
    q, qd = ca.SX.sym("q", n), ca.SX.sym("qd", n)
    qdd, lam = ca.SX.sym("qdd", n), ca.SX.sym("lam", rows.count)
    W = model.motion.W(t)
    phi = ca.vertcat(
        *[
            ca.mtimes(symbolic_point_row(c + v * W, o, model.n, model.spec.length), q)
            for o, c, v in zip(rows.orders, rows.offsets, rows.rates)
        ]
    )
    A = ca.jacobian(phi, q)
    phidot = ca.mtimes(A, qd) + ca.jacobian(phi, t)
    h = -(ca.mtimes(ca.jacobian(phidot, q), qd) + ca.jacobian(phidot, t))
    Kt, f = link.terms(model.rigid(t), model.driven_end, model.axial_shortening)
    alg = ca.vertcat(
        ca.mtimes(ca.DM(model.M), qdd) + ca.mtimes(A.T, lam) - (f - ca.mtimes(Kt, q)),
        ca.mtimes(A, qdd) - h + 2 * gamma * phidot + beta**2 * phi,
    )
    return {
        "x": ca.vertcat(q, qd),
        "z": ca.vertcat(qdd, lam),
        "t": t,
        "ode": ca.vertcat(qd, qdd),
        "alg": alg,
    }


def _consistent_start(model: RPArmModel, q0: Array) -> Array:
    """``(qdd, lam)`` at rest at ``q0`` (Eqs 55-56): IDAS's initial guess for the algebraic part."""
    n, m = model.ndof, model.rows.count
    prob = model.problem()
    S = np.block(
        [
            [model.M, prob.phi_q(q0, 0.0).T],
            [prob.phi_q(q0, 0.0), np.zeros((m, m))],
        ]
    )
    return np.linalg.solve(
        S, np.concatenate([prob.force(q0, np.zeros(n), 0.0), prob.h(q0, np.zeros(n), 0.0)])
    )
