"""The NMPC's prediction model: the design model, or its Galerkin truncation to fewer modes per link.

The NMPC predicts with RK4, whose stable step is bounded by the fastest mode: on the
three-link arm with two assumed modes per link (``amm:2``, 18 states) the second modes
are at 1464-2045 rad/s (target (80, -10, -10) deg, 2 kg), so a 10 ms sample needs 9 RK4
steps, and every step one Jacobian of ``f`` in the sensitivities.  Those modes are far
beyond what a 100 Hz controller can act on (Nyquist 314 rad/s); the first modes
(344-470 rad/s) need 2 RK4 steps.  ``prediction_modes = k`` predicts with the first
``k`` modes of every link and leaves the others to the estimator and the plant.

Truncation.  With ``q = P q_r`` (``P`` selects the joints and the kept elastic
coordinates; the others are held at zero), the reduced equations are the Galerkin
projection of the design model's, ``P' M(Pq_r) P qdd_r = P' (B u - c - g - K q - D qd)``,
built from the model's own ``M, c, g, K, D`` (so it needs no rebuild of the arm, holds
for frozen and scheduled modes, and is exact Lagrangian mechanics of the constrained
system: its kinetic and potential energies are the design model's restricted to
``q = P q_r``).  For assumed modes whose shapes do not depend on their number (the
link's own eigenfunctions) this is the ``amm:k`` model of the same arm.

The controller maps the estimated state to the prediction's coordinates by the same
selection, ``x_r = x[keep]`` (:attr:`Prediction.keep`), and regulates about the
prediction model's own equilibrium at the target joint angles.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from flexctrl.errors import SpecError


@dataclass(frozen=True)
class Prediction:
    """The prediction model and how the design model's state maps onto it.

    Attributes
    ----------
    model : Model
        The model the NMPC predicts with (the design model itself when nothing is dropped).
    keep : ndarray of int
        Indices of the design model's state ``x = (q, qd)`` kept, in order.
    reduced : bool
        True when ``model`` is a truncation.
    """

    model: object
    keep: np.ndarray
    reduced: bool


def _kept_coordinates(model, modes: int) -> np.ndarray:
    info = getattr(model, "info", {}) or {}
    n_modes = info.get("n_modes")
    if info.get("family") != "amm" or n_modes is None:
        raise SpecError(f"prediction_modes = {modes} needs an assumed-modes design model ('amm:N'); "
                        f"the design model is {getattr(model, 'fidelity', '?')}", key="prediction_modes")
    n = model.n_u
    keep = list(range(n))
    offset = n
    for count in n_modes:
        keep += [offset + j for j in range(min(modes, int(count)))]
        offset += int(count)
    if offset != model.n_q:
        raise SpecError(f"the design model's modes per link {list(n_modes)} do not add up to its "
                        f"{model.n_q - n} elastic coordinates", key="prediction_modes")
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
    info = dict(model.info, n_modes=n_modes, truncated_from=str(model.fidelity), kept_coordinates=keep_q.tolist())
    fidelity = replace(model.fidelity, count=max(n_modes)) if getattr(model.fidelity, "kind", None) == "amm" else model.fidelity
    return projected_model(model, P, names, f"{model.name} (first {modes} modes per link)", fidelity, info), keep_q


def projected_model(model, basis: np.ndarray, names, name: str, fidelity, info: dict):
    """The Galerkin projection of ``model`` onto ``q = basis q_r`` (``basis``: N x N_r, joints first)."""
    from flexctrl.dynamics.model import Model

    N, Nr, n = model.n_q, basis.shape[1], model.n_u
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
        "K": ca.Function("K", [q], [K_r], ["q"], ["K"], opts) if scheduled else ca.Function("K", [], [ca.DM(ca.evalf(K_r))], [], ["K"]),
        "D": ca.Function("D", [q], [D_r], ["q"], ["D"], opts) if fn["D"].n_in() > 0
        else ca.Function("D", [], [ca.DM(ca.evalf(D_r))], [], ["D"]),
        "f": ca.Function("f", [x, u], [ca.vertcat(qd, qdd)], ["x", "u"], ["xdot"], opts),
        "energies": ca.Function("energies", [q, qd], list(energies), ["q", "qd"], ["E_kin", "E_el", "E_grav"], opts),
        "tip": ca.Function("tip", [q, qd], list(tip), ["q", "qd"], ["p", "v"], opts),
        "hubs": ca.Function("hubs", [q], [fn["hubs"](qf)], ["q"], ["p"], opts),
        "deflection": ca.Function("deflection", [q], [w, dw], ["q"], ["w", "dw"], opts),
    }
    return Model(name, fidelity, model.n_joints, tuple(names), functions, model.omega_max, spec=model.spec, info=info)


def prediction_model(model, modes: int) -> Prediction:
    """The NMPC's :class:`Prediction` for ``prediction_modes = modes`` (0: the design model itself)."""
    if modes <= 0 or model.n_q == model.n_u:
        return Prediction(model, np.arange(model.n_x), False)
    reduced, keep_q = truncated_model(model, modes)
    if reduced.n_q == model.n_q:
        return Prediction(model, np.arange(model.n_x), False)
    return Prediction(reduced, np.r_[keep_q, model.n_q + keep_q], True)


__all__ = ["Prediction", "prediction_model", "truncated_model"]
