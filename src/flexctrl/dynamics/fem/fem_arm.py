"""Planar revolute arm with flexible links as a floating-frame finite-element model.

After Pan, Scott & Ulsoy (1990): each link is a beam of ``N`` equal elements,
Hermite cubics for bending and linear elements for the axial displacement, with
EA from :meth:`~flexctrl.spec.arm.LinkSpec.axial_stiffness` (Eqs 10, 29-33); hubs
and payload are rigid bodies; the joint angles are solved together with the
nodal coordinates under prescribed joint torques (full coupling, Eqs 35, 43).
The result presents the :class:`~flexctrl.dynamics.model.Model` interface.
Decisions are argued in ``docs/explanation/finite-elements.md``; in short:

Joint compatibility eliminated exactly (clamped frames)
    Pan imposes Eqs 19-20 (displacement and slope continuity at every revolute
    joint) as constraints with multipliers.  In the plane those constraints are
    linear in the nodal coordinates, so they can be solved for the base dofs of
    every link instead: the frame of link ``i`` then sits at the *deformed* tip of
    link ``i-1``, turned by its tip slope, and link ``i`` is clamped in it
    (``u_0 = w_0 = theta_0 = 0``).  The equations become an ODE
    ``M(q) qdd + c(q, qd) + g(q) + K q + D qd = B tau`` -- the same form as the
    assumed-modes model, so simulation, linearisation and MPC take either.  The
    frame of link ``i`` turns by ``alpha_i = alpha_{i-1} + theta_N^{i-1} + q_i``
    (an exact rotation by the nodal slope; Subedi's Eq 7 linearises it, which
    differs at second order).  ``q_i`` is therefore the joint angle proper.

Kinematics, kinetic energy and axial shortening
    See :mod:`flexctrl.dynamics.fem.arm_kinematics`: each link's ``T`` is exact for
    the floating-frame kinematics; axial shortening enters through the membrane
    strain ``u' + 1/2 w'^2`` of the axial elements (Pan's geometric stiffness of the
    axial force from inertia, gravity, outboard links and payload, Eqs 16-18).
    ``K`` is the stiffness at ``q = 0``; ``g`` carries the rest of the potential
    forces: ``g = dU_g/dq + dU_el/dq - K q``.

Forward dynamics
    The mass matrix has an arrowhead structure (interior nodes couple only to their
    neighbours, the joints and the inboard link tips), so ``f`` solves
    ``M qdd = rhs`` by a symbolic sparse LDL^T (:mod:`.sparse_ldl`) that eliminates
    interior dofs first; the expression grows linearly with ``N``.

Damping
    Joint friction ``b`` on the joint rows; structural damping stiffness-proportional
    per link, ``D_i = (2 zeta_i / omega_1i) K_i``, where ``zeta_i`` is the link's
    first ``damping_ratio`` and ``omega_1i`` its first clamped-mass frequency at the
    reference configuration (so the first mode has ratio ``zeta_i``, higher modes more).

Coordinates: ``q1..qn`` then, link by link, ``w<i>_<k>, th<i>_<k>`` (nodes ``k = 1..N``)
and ``u<i>_<k>`` (m, rad, m).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import casadi as ca
import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike

from flexctrl.dynamics.fem.arm_kinematics import (
    MAX_ELEMENTS,
    FemExpressions,
    fem_coordinate_names,
    fem_expressions,
    locked_matrices,
)
from flexctrl.dynamics.fem.sparse_ldl import ldl_solve_sparse
from flexctrl.dynamics.model import Model
from flexctrl.modal.fem_modes import link_frequencies_fem
from flexctrl.spec.arm import ArmSpec
from flexctrl.spec.fidelity import Fidelity

__all__ = [
    "MAX_ELEMENTS",
    "FemExpressions",
    "build_fem_model",
    "fem_coordinate_names",
    "fem_expressions",
    "generalized_frequencies",
    "locked_frequencies",
    "locked_matrices",
    "relax_axial",
]


def build_fem_model(
    arm: ArmSpec,
    n_elements: int,
    *,
    axial_shortening: bool = True,
    reference_q: Sequence[float] | np.ndarray | None = None,
) -> Model:
    """Build the floating-frame finite-element model of a planar revolute arm.

    Parameters
    ----------
    arm
        Validated arm (revolute joints only; payload, gravity, damping from it).
    n_elements
        Elements per link, 1..64.
    axial_shortening
        Include the axial-shortening (geometric stiffness) terms (module docstring).
    reference_q
        Joint angles (rad) of ``omega_max``, the locked frequencies in ``info`` and
        the damping calibration; default the arm's ``configuration``.

    Returns
    -------
    Model
        Functions ``M, c, g, K, D, f, energies, tip, hubs, deflection``; coordinates
        ``q1..qn`` then nodal names (see :func:`fem_coordinate_names`).

    Raises
    ------
    SpecError
        For an element count out of range, a prismatic joint or a link without EA.

    Examples
    --------
    >>> from flexctrl.spec.arm import load_arm
    >>> model = build_fem_model(load_arm("models/subedi3link.toml"), 2)
    >>> model.coordinate_names[:7]
    ('q1', 'q2', 'q3', 'w1_1', 'th1_1', 'w1_2', 'th1_2')
    >>> str(model.fidelity), model.n_q
    ('fem:2', 21)
    """
    start = time.perf_counter()
    ex = fem_expressions(arm, n_elements, axial_shortening)
    n, N = arm.n_links, int(n_elements)
    q_ref = arm.configuration_or_default(reference_q)
    K_np, D_np, link_omega1 = _stiffness_and_damping(arm, ex, q_ref, N)
    functions = _fem_functions(ex, K_np, D_np, n, axial_shortening)
    locked = locked_frequencies(functions, K_np, q_ref, n)
    info = {
        "family": "fem",
        "n_elements": N,
        "axial_shortening": bool(axial_shortening),
        "EA_N": list(ex.EA),
        "reference_q": q_ref.tolist(),
        "locked_frequencies_rad_s": locked.tolist(),
        "link_first_frequencies_rad_s": link_omega1,
        "joint_compatibility": "eliminated: link i clamped in a frame at the deformed tip of "
        "link i-1",
        "elastic_rotation": "exact rotation by the nodal tip slope theta_N",
        "g_convention": "dU_g/dq + dU_el/dq - K q" if axial_shortening else "dU_g/dq",
        "axial_strain": "u' + 1/2 mean_e(w'^2)" if axial_shortening else "u'",
        "damping": "joint friction; stiffness-proportional per link, 2 zeta / omega_1 K",
        "solver": "symbolic sparse LDL^T, interior nodes eliminated first",
        "input_matrix": "tau acts on q1..qn",
        "build_time_s": time.perf_counter() - start,
    }
    return Model(
        name=f"{arm.name} fem {N}{'' if axial_shortening else ' no-shortening'}",
        fidelity=Fidelity("fem", N),
        n_joints=n,
        coordinate_names=fem_coordinate_names(n, N),
        functions=functions,
        omega_max=float(locked.max()),
        spec=arm,
        info=info,
    )


def _stiffness_and_damping(
    arm: ArmSpec, ex: FemExpressions, q_ref: np.ndarray, n_elements: int
) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """``(K, D, omega_1)``: the stiffness at ``q = 0``, the damping (joint friction, and per
    link ``(2 zeta / omega_1) K``) and each link's first clamped-mass frequency (rad/s)."""
    n, lay = arm.n_links, ex.layout
    K_np = ex.stiffness()
    D_np = np.diag([j.friction for j in arm.joints] + [0.0] * (lay.size - n))
    link_omega1 = []
    for i, link in enumerate(arm.links):
        w1 = 2 * math.pi * float(link_frequencies_fem(arm, q_ref, i, 1, n_elements)[0])
        link_omega1.append(w1)
        zeta = link.damping_ratio(0)
        if zeta > 0.0:
            idx = np.concatenate([lay.w[i], lay.u[i]])
            D_np[np.ix_(idx, idx)] += (2.0 * zeta / w1) * K_np[np.ix_(idx, idx)]
    return K_np, D_np, link_omega1


def _fem_functions(
    ex: FemExpressions, K_np: np.ndarray, D_np: np.ndarray, n: int, axial_shortening: bool
) -> dict[str, ca.Function]:
    """Lagrange's equations solved for ``qdd`` and the model's named Functions."""
    lay = ex.layout
    nq = lay.size
    q, M, U_g, U_el = ex.q, ex.mass_matrix, ex.gravity_energy, ex.elastic_energy
    qd, u = ca.SX.sym("qd", nq), ca.SX.sym("u", n)
    K, D = ca.sparsify(ca.DM(K_np)), ca.sparsify(ca.DM(D_np))
    Mqd = ca.mtimes(M, qd)
    E_kin = 0.5 * ca.dot(qd, Mqd)
    c = ca.jtimes(Mqd, q, qd) - ca.gradient(E_kin, q)
    g = ca.gradient(U_g, q)
    if axial_shortening:
        g = g + ca.gradient(U_el, q) - ca.mtimes(K, q)
    B = ca.vertcat(ca.SX.eye(n), ca.SX.zeros(nq - n, n))
    rhs = ca.mtimes(B, u) - c - g - ca.mtimes(K, q) - ca.mtimes(D, qd)
    qdd = ldl_solve_sparse(M, rhs, lay.elimination_order())
    E_el = U_el
    x = ca.vertcat(q, qd)
    hubs = ex.positions
    tip = hubs[:, n]
    opts = {"cse": True}
    return {
        "M": ca.Function("M", [q], [M], ["q"], ["M"], opts),
        "c": ca.Function("c", [q, qd], [c], ["q", "qd"], ["c"], opts),
        "g": ca.Function("g", [q], [g], ["q"], ["g"], opts),
        "K": ca.Function("K", [], [K], [], ["K"]),
        "D": ca.Function("D", [], [D], [], ["D"]),
        "f": ca.Function("f", [x, u], [ca.vertcat(qd, qdd)], ["x", "u"], ["xdot"], opts),
        "energies": ca.Function(
            "energies", [q, qd], [E_kin, E_el, U_g], ["q", "qd"], ["E_kin", "E_el", "E_grav"], opts
        ),
        "tip": ca.Function(
            "tip", [q, qd], [tip, ca.jtimes(tip, q, qd)], ["q", "qd"], ["p", "v"], opts
        ),
        "hubs": ca.Function("hubs", [q], [hubs], ["q"], ["p"], opts),
        "deflection": ca.Function(
            "deflection", [q], [ex.tip_deflection, ex.tip_slope], ["q"], ["w", "dw"], opts
        ),
    }


def locked_frequencies(functions: dict, K: np.ndarray, q_r: ArrayLike, n_joints: int) -> np.ndarray:
    """Locked-joint natural frequencies (rad/s, ascending) at joint angles ``q_r``.

    The joints clamped, the elastic dofs at zero, no gravity preload; see
    :func:`generalized_frequencies`.

    Parameters
    ----------
    functions : dict of str to casadi.Function
        The model's Functions (``M`` is read).
    K : ndarray
        The stiffness (N x N).
    q_r : array_like
        Joint angles, rad.
    n_joints : int
        Joint coordinates first in ``q``.

    Returns
    -------
    ndarray
        Frequencies, rad/s, ascending.
    """
    nq = K.shape[0]
    q0 = np.concatenate([np.asarray(q_r, dtype=float), np.zeros(nq - n_joints)])
    M0 = np.array(functions["M"](q0))
    f = slice(n_joints, nq)
    return generalized_frequencies(K[f, f], 0.5 * (M0[f, f] + M0[f, f].T))


def generalized_frequencies(K: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``sqrt`` of the eigenvalues of ``K v = lambda M v`` (rad/s, ascending), ``K`` definite.

    Solved as ``M v = mu K v``, ``lambda = 1/mu``: with the stiff axial elements
    ``||K||`` exceeds the lowest eigenvalues by 1e7 and more, and the direct
    ``eigh(K, M)`` loses the lowest frequencies to rounding (relative errors ~1e-7
    instead of ~1e-10, which hides the h^4 convergence).

    Parameters
    ----------
    K : ndarray
        Stiffness, positive definite.
    M : ndarray
        Mass, symmetric.

    Returns
    -------
    ndarray
        Frequencies, rad/s, ascending (positive ``mu`` only).
    """
    mu = scipy.linalg.eigh(M, K, eigvals_only=True)
    mu = mu[mu > 0.0]
    return np.sort(np.sqrt(1.0 / mu))


def relax_axial(model: Model, q: ArrayLike) -> np.ndarray:
    """``q`` with its axial dofs set to minimise the elastic energy for the given bending dofs.

    With axial shortening this makes the links inextensible (``u = -s``, zero
    membrane strain): the consistent way to start from a bent shape without
    loading the stiff axial elements.  Without axial shortening it sets ``u = 0``.

    Parameters
    ----------
    model : Model
        A finite-element model (its axial dofs are the coordinates named ``u*``).
    q : array_like
        Coordinates (rad, m).

    Returns
    -------
    ndarray
        ``q`` with the axial dofs relaxed, m.
    """
    relaxed = np.asarray(q, dtype=float).copy()
    idx = np.array(
        [k for k, name in enumerate(model.coordinate_names) if name.startswith("u")], dtype=int
    )
    qs = ca.SX.sym("q", model.n_q)
    E_el = model.functions["energies"](qs, ca.SX.zeros(model.n_q))[1]
    grad = ca.gradient(E_el, qs)[idx]
    fun = ca.Function("axial", [qs], [grad, ca.jacobian(grad, qs)[:, idx]])
    for _ in range(3):  # quadratic in u: one step is exact up to rounding
        g, H = (np.asarray(v, dtype=float) for v in fun(relaxed))
        relaxed[idx] -= np.linalg.solve(H, g.ravel())
    return relaxed
