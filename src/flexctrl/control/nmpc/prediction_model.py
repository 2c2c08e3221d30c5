"""The NMPC's prediction model: the design model, or its Galerkin truncation to fewer modes.

The NMPC predicts with RK4, whose stable step is bounded by the fastest mode: with two
assumed modes per link the second modes of the three-link arm are far beyond what a 100 Hz
controller can act on (its Nyquist frequency), yet they set the RK4 substeps, and every
substep costs one Jacobian of ``f`` in the sensitivities.  ``prediction_modes = k`` predicts
with the first ``k`` modes of every link and leaves the others to the estimator and the
plant.

Truncation.  With ``q = P q_r`` (``P`` selects the joints and the kept elastic
coordinates; the others are held at zero), the reduced equations are the Galerkin
projection of the design model's, ``P' M(Pq_r) P qdd_r = P' (B u - c - g - K q - D qd)``,
built from the model's own ``M, c, g, K, D`` (so it needs no rebuild of the arm, holds
for frozen and scheduled modes, and is exact Lagrangian mechanics of the constrained
system: its kinetic and potential energies are the design model's restricted to
``q = P q_r``).  For assumed modes whose shapes do not depend on their number (the
link's own eigenfunctions) this is the ``amm:k`` model of the same arm.

Mapping the estimate.  The kept assumed-mode coordinates of the design model are not
its slow modes: the mass matrix couples them to the dropped ones, so ``x[keep]``
carries the fast (second) modes, and feeding them back through gains designed on the
slow model is observation spillover, enough to make the sampled loop of the tuned NMPC
(``controllers/nmpc.toml``) unstable about its target.  :func:`modal_map` removes them
first: with ``Phi`` the design model's modes at the target (``K_lin Phi = M Phi Omega^2``,
M-orthonormal) and ``Phi_s`` the slowest ones, as many as the coordinates kept, the
prediction sees ``q_r = P' Phi_s Phi_s' M q`` (``q = P q_r`` its basis: a selection, or
:func:`coupled_basis`; the same map for ``qd``): the fast modes are in its null space, so
in modal coordinates the linear loop is block triangular (fast modes open-loop, lightly
damped and stable; slow modes under the reduced design's feedback).  The map alone is not
enough: the first assumed mode per link puts the lowest elastic mode well above the design
model's, and that NMPC still oscillates; the coupled basis (:func:`coupled_basis`) keeps
the slow frequencies, and with the map the loop settles.  Joint displacements map to
themselves where they are rigid-body modes.  The map is affine about the equilibria,
``x_r = x_op,r + T (x - x_op)``, and the torque is passed on as a deviation,
``u = u_op + (u_r - u_op,r)``, so the design model's equilibrium is the loop's.
``prediction_map = "select"`` keeps ``x_r = x[keep]`` (:attr:`Prediction.keep`).  The
controller regulates about the prediction model's own equilibrium at the target joint
angles.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import casadi as ca
import numpy as np
import scipy.linalg as sl

from flexctrl.dynamics.model import Model
from flexctrl.errors import SpecError


@dataclass(frozen=True)
class Prediction:
    """The prediction model and how the design model's state maps onto it.

    Attributes
    ----------
    model : Model or None
        The model the NMPC predicts with (None: the design model itself, nothing dropped).
    keep : ndarray of int
        Indices of the design model's state ``x = (q, qd)`` kept, in order.
    reduced : bool
        True when ``model`` is a truncation.
    state_map : ndarray or None
        ``T`` of ``x_r = x_op,r + T (x - x_op)`` (:func:`modal_map`); None: ``x_r = x[keep]``.
    """

    model: Model | None
    keep: np.ndarray
    reduced: bool
    state_map: np.ndarray | None = None


def _kept_coordinates(model, modes: int) -> np.ndarray:
    info = getattr(model, "info", {}) or {}
    n_modes = info.get("n_modes")
    if info.get("family") != "amm" or n_modes is None:
        raise SpecError(
            f"prediction_modes = {modes} needs an assumed-modes design model ('amm:N'); "
            f"the design model is {getattr(model, 'fidelity', '?')}",
            key="prediction_modes",
        )
    n = model.n_u
    keep = list(range(n))
    offset = n
    for count in n_modes:
        keep += [offset + j for j in range(min(modes, int(count)))]
        offset += int(count)
    if offset != model.n_q:
        raise SpecError(
            f"the design model's modes per link {list(n_modes)} do not add up to its "
            f"{model.n_q - n} elastic coordinates",
            key="prediction_modes",
        )
    return np.asarray(keep, dtype=int)


def truncated_model(model, modes: int):
    """The design ``model`` with at most ``modes`` assumed modes per link (Galerkin truncation).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        An assumed-modes model (``info["family"] == "amm"``).
    modes : int
        Elastic modes kept per link (the lowest ones).

    Returns
    -------
    tuple
        ``(reduced_model, q_keep)``: a :class:`~flexctrl.dynamics.model.Model` with the
        required functions on the kept coordinates, and their indices in ``q``.
    """
    keep_q = _kept_coordinates(model, modes)
    P = np.zeros((model.n_q, keep_q.size))
    P[keep_q, np.arange(keep_q.size)] = 1.0
    names = tuple(model.coordinate_names[i] for i in keep_q)
    n_modes = [min(modes, int(c)) for c in model.info["n_modes"]]
    info = dict(
        model.info,
        n_modes=n_modes,
        truncated_from=str(model.fidelity),
        kept_coordinates=keep_q.tolist(),
    )
    fidelity = (
        replace(model.fidelity, count=max(n_modes))
        if getattr(model.fidelity, "kind", None) == "amm"
        else model.fidelity
    )
    return projected_model(
        model, P, names, f"{model.name} (first {modes} modes per link)", fidelity, info
    ), keep_q


def projected_model(model, basis: np.ndarray, names, name: str, fidelity, info: dict):
    """The Galerkin projection of ``model`` onto ``q = basis q_r``.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model.
    basis : ndarray
        ``P`` (N x N_r), the joints first.
    names : sequence of str
        The reduced coordinates' names.
    name : str
        The reduced model's name.
    fidelity
        Its fidelity.
    info : dict
        Its ``info``.

    Returns
    -------
    flexctrl.dynamics.model.Model
        With ``M, c, g, K, D, f, energies, tip, hubs, deflection`` on the reduced coordinates.
    """
    Nr, n = basis.shape[1], model.n_u
    P = ca.SX(ca.sparsify(ca.DM(basis)))
    fn = model.functions
    q, qd, u = ca.SX.sym("q", Nr), ca.SX.sym("qd", Nr), ca.SX.sym("u", n)
    qf, qdf = ca.mtimes(P, q), ca.mtimes(P, qd)
    project = lambda e: ca.mtimes(P.T, e)  # noqa: E731
    scheduled = fn["K"].n_in() > 0
    K = ca.SX(fn["K"](qf) if scheduled else fn["K"]()["K"])
    D = ca.SX(fn["D"](qf) if fn["D"].n_in() > 0 else fn["D"]()["D"])
    M_r = ca.mtimes([P.T, fn["M"](qf), P])
    c_r, g_r = project(fn["c"](qf, qdf)), project(fn["g"](qf))
    K_r, D_r = ca.mtimes([P.T, K, P]), ca.mtimes([P.T, D, P])
    B = ca.vertcat(ca.SX.eye(n), ca.SX.zeros(Nr - n, n))
    rhs = ca.mtimes(B, u) - c_r - g_r - ca.mtimes(K_r, q) - ca.mtimes(D_r, qd)
    qdd = ca.solve(M_r, rhs)
    x = ca.vertcat(q, qd)
    opts = {"cse": True}
    energies = fn["energies"](qf, qdf)
    tip = fn["tip"](qf, qdf)
    w, dw = fn["deflection"](qf)
    functions = {
        "M": ca.Function("M", [q], [M_r], ["q"], ["M"], opts),
        "c": ca.Function("c", [q, qd], [c_r], ["q", "qd"], ["c"], opts),
        "g": ca.Function("g", [q], [g_r], ["q"], ["g"], opts),
        "K": ca.Function("K", [q], [K_r], ["q"], ["K"], opts)
        if scheduled
        else ca.Function("K", [], [ca.DM(ca.evalf(K_r))], [], ["K"]),
        "D": ca.Function("D", [q], [D_r], ["q"], ["D"], opts)
        if fn["D"].n_in() > 0
        else ca.Function("D", [], [ca.DM(ca.evalf(D_r))], [], ["D"]),
        "f": ca.Function("f", [x, u], [ca.vertcat(qd, qdd)], ["x", "u"], ["xdot"], opts),
        "energies": ca.Function(
            "energies", [q, qd], list(energies), ["q", "qd"], ["E_kin", "E_el", "E_grav"], opts
        ),
        "tip": ca.Function("tip", [q, qd], list(tip), ["q", "qd"], ["p", "v"], opts),
        "hubs": ca.Function("hubs", [q], [fn["hubs"](qf)], ["q"], ["p"], opts),
        "deflection": ca.Function("deflection", [q], [w, dw], ["q"], ["w", "dw"], opts),
    }
    return Model(
        name,
        fidelity,
        model.n_joints,
        tuple(names),
        functions,
        model.omega_max,
        spec=model.spec,
        info=info,
    )


def coupled_basis(mass: np.ndarray, a_lin: np.ndarray, n_joints: int, n_elastic: int) -> np.ndarray:
    """``q = P q_r``: the joints, and the elastic parts of the design model's slowest modes.

    ``P = blockdiag(I, E)`` with ``E`` (orthonormal columns, ``n_elastic`` of them) the
    dominant directions of the elastic components of the ``n_joints + n_elastic``
    slowest modes of ``K_lin Phi = M Phi Omega^2`` (``mass``, ``a_lin`` as in
    :func:`modal_map`).  Where the rigid-body modes carry no elastic motion (no gravity
    stiffness, as in the horizontal plane) the span of ``P`` holds those modes exactly,
    so the Galerkin projection keeps their frequencies at the target (the first
    assumed mode per link does not).

    Parameters
    ----------
    mass : ndarray
        The design model's mass matrix at the target (N x N).
    a_lin : ndarray
        Its continuous linearization ``A`` at the target (2N x 2N).
    n_joints : int
        Joints.
    n_elastic : int
        Elastic directions kept.

    Returns
    -------
    ndarray
        ``P`` (N x (n_joints + n_elastic)).
    """
    N = mass.shape[0]
    M = 0.5 * (mass + mass.T)
    K = M @ -a_lin[N:, :N]
    _, Phi = sl.eigh(0.5 * (K + K.T), M)
    U, _, _ = np.linalg.svd(Phi[n_joints:, : n_joints + n_elastic], full_matrices=False)
    return sl.block_diag(np.eye(n_joints), U[:, :n_elastic])


def prediction_model(
    model,
    modes: int,
    *,
    basis: str = "assumed",
    mapping: str = "select",
    mass: np.ndarray | None = None,
    a_lin: np.ndarray | None = None,
) -> Prediction:
    """The NMPC's :class:`Prediction` for ``prediction_modes = modes``.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model.
    modes : int
        Elastic modes per link predicted with; 0: the design model itself.
    basis : {"assumed", "coupled"}
        The first ``modes`` assumed modes per link (:func:`truncated_model`), or as many
        coordinates of :func:`coupled_basis`.
    mapping : {"select", "modal"}
        How the design state maps onto the prediction's (:func:`modal_map` for ``"modal"``).
    mass, a_lin : ndarray, optional
        The design model's mass matrix and continuous linearization at the target, which the
        coupled basis and the modal map need.

    Returns
    -------
    Prediction
    """
    if modes <= 0 or model.n_q == model.n_u:
        return Prediction(model, np.arange(model.n_x), False)
    reduced, keep_q = truncated_model(model, modes)
    if reduced.n_q == model.n_q:
        return Prediction(model, np.arange(model.n_x), False)
    keep = np.r_[keep_q, model.n_q + keep_q]
    if basis == "assumed" and mapping == "select":
        return Prediction(reduced, keep, True)
    if mass is None or a_lin is None:
        raise ValueError(
            f"prediction basis {basis!r} with mapping {mapping!r} needs the mass matrix and "
            "the linearization"
        )
    if basis == "coupled":
        P = coupled_basis(mass, a_lin, model.n_u, keep_q.size - model.n_u)
        reduced = _coupled_model(model, P, reduced.fidelity)
    elif basis == "assumed":
        P = np.zeros((model.n_q, keep_q.size))
        P[keep_q, np.arange(keep_q.size)] = 1.0
    else:
        raise ValueError(
            f"prediction basis {basis!r} is not allowed; allowed: 'assumed', 'coupled'"
        )
    if mapping == "modal":
        T = modal_map(mass, a_lin, P)
    elif mapping == "select":
        T = np.kron(np.eye(2), np.linalg.pinv(P))
    else:
        raise ValueError(
            f"prediction mapping {mapping!r} is not allowed; allowed: 'modal', 'select'"
        )
    return Prediction(reduced, keep, True, T)


def _coupled_model(model, P: np.ndarray, fidelity):
    """The projection of ``model`` onto the coupled basis ``P`` (:func:`coupled_basis`)."""
    n = model.n_u
    names = tuple(model.coordinate_names[:n]) + tuple(f"eta{j + 1}" for j in range(P.shape[1] - n))
    info = dict(model.info, truncated_from=str(model.fidelity), basis="coupled")
    label = f"{model.name} (slowest {P.shape[1] - n} coupled modes)"
    return projected_model(model, P, names, label, fidelity, info)


def modal_map(mass: np.ndarray, a_lin: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """``T`` of ``x_r = T x``: the reduced coordinates of the slow-mode part of the design state.

    Parameters
    ----------
    mass : ndarray
        The design model's mass matrix at the target (N x N).
    a_lin : ndarray
        The continuous linearisation ``A`` at the target equilibrium (2N x 2N), whose
        lower-left block is ``-M^-1 K_lin`` (stiffness and gravity).
    basis : ndarray
        ``P`` of the prediction's coordinates, ``q = P q_r`` (N x N_r, orthonormal
        columns: a selection of coordinates, or :func:`coupled_basis`).

    Returns
    -------
    ndarray
        ``blockdiag(P' P_s, P' P_s)`` with ``P_s = Phi_s Phi_s' M`` the M-orthogonal
        projector onto the ``N_r`` slowest modes: zero on the dropped modes (see the
        module docstring).

    Raises
    ------
    ValueError
        When the slow modes do not span the reduced coordinates (``P' Phi_s`` singular).
    """
    N = mass.shape[0]
    M = 0.5 * (mass + mass.T)
    K = M @ -a_lin[N:, :N]
    _, Phi = sl.eigh(0.5 * (K + K.T), M)
    Ps = Phi[:, : basis.shape[1]]
    SPhi = basis.T @ Ps
    cond = np.linalg.cond(SPhi)
    if not np.isfinite(cond) or cond > 1e8:
        raise ValueError(
            f"the {basis.shape[1]} slowest modes do not span the prediction's coordinates "
            f'(condition number {cond:.3g}); use prediction_map = "select"'
        )
    Tq = SPhi @ Ps.T @ M
    return sl.block_diag(Tq, Tq)


__all__ = ["Prediction", "prediction_model", "truncated_model", "modal_map", "coupled_basis"]
