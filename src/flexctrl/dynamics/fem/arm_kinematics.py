"""Kinematics, mass matrix and energies of the finite-element arm (:mod:`.fem_arm`).

Kinematics and kinetic energy of link i (Eqs 2-6, 30)
    In the frame ``(r_i, R(alpha_i))`` a material point ``x`` is at
    ``(x + u, w)``; with frame velocity ``v_b = R^T r_i'`` and rate ``omega``,
    ``V = v_b + omega J (x + u, w) + (u', w')``.  ``T = 1/2 nu^T G nu`` with
    ``nu = (v_b, omega, q_w', q_u')`` and ``G`` from the integrals of
    :mod:`flexctrl.dynamics.fem.link_matrices` (the rigid part uses the file's link
    inertia, ``J_l + m L^2/4``, like the assumed-modes model).
    ``M = sum J_nu^T G J_nu`` over links, plus hubs (mass at the joint, rotor turning
    with the link) and payload (mass at the tip, inertia turning with the tip slope).

Axial shortening (Eqs 11-18), switchable
    ``u`` is the axial displacement of the neutral axis itself, so a bent link whose
    fibres keep their length has ``u(x) = -s(x)``, ``s = 1/2 int_0^x w'^2`` (Eq 14).
    With ``axial_shortening=True`` the axial strain is the membrane strain
    ``eps = u' + 1/2 w'^2`` (``w'^2`` averaged over each element, which keeps the
    linear axial elements free of membrane locking), i.e.
    ``U_el = 1/2 q_w^T K_w q_w + 1/2 sum_e EA l_e eps_e^2``.  Expanding about any
    motion, ``EA eps_e`` is the axial force the elements carry -- the inertia of the
    part beyond, gravity, the outboard links and the payload (Eqs 17-18) -- and the
    ``1/2 w'^2`` term contributes ``1/2 int F w'^2`` (Eq 16): Pan's geometric
    stiffness, here with the axial force taken from the axial dofs (element
    averages) rather than from a separate rigid-body analysis.  Kinetic energy stays
    exact and quadratic in the velocities, so ``M`` is positive definite at every
    state, the undamped model conserves ``T + U``, and under full coupling the joint
    accelerations enter the axial force through the equations themselves.  (A
    Lagrangian term built from the *nominal* rigid motion instead is a second-order
    truncation of ``T`` and leaves ``M`` indefinite at tip slopes of a few milliradians;
    see ``docs/explanation/finite-elements.md``.)  ``axial_shortening=False`` uses the linear
    strain ``eps = u'``.  ``K`` is the stiffness at ``q = 0`` (the Hessian of
    ``U_el``); ``g`` carries the rest: ``g = dU_g/dq + dU_el/dq - K q``.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike

from flexctrl.dynamics.fem.link_matrices import LinkMatrices, link_matrices
from flexctrl.errors import SpecError
from flexctrl.spec.arm import ArmSpec
from flexctrl.spec.joint_support import require_revolute

MAX_ELEMENTS = 64


def _rot(angle):
    c, s = ca.cos(angle), ca.sin(angle)
    return ca.vertcat(ca.horzcat(c, -s), ca.horzcat(s, c))


def fem_coordinate_names(n_links: int, n_elements: int) -> tuple[str, ...]:
    """``q1..qn``, then per link ``w<i>_<k>, th<i>_<k>`` for ``k = 1..N`` and ``u<i>_<k>``.

    Parameters
    ----------
    n_links : int
        Links, hence joints.
    n_elements : int
        Elements per link ``N``.

    Returns
    -------
    tuple of str
        Joint angles (rad), then each link's nodal deflections (m), slopes (rad) and axial
        displacements (m).
    """
    names = [f"q{i + 1}" for i in range(n_links)]
    for i in range(n_links):
        for k in range(1, n_elements + 1):
            names += [f"w{i + 1}_{k}", f"th{i + 1}_{k}"]
        names += [f"u{i + 1}_{k}" for k in range(1, n_elements + 1)]
    return tuple(names)


class _Layout:
    """Index bookkeeping of the coordinate vector."""

    def __init__(self, n_links: int, n_elements: int):
        self.n, self.N = n_links, n_elements
        per = 3 * n_elements
        self.size = n_links + n_links * per
        self.w = [
            np.arange(n_links + i * per, n_links + i * per + 2 * n_elements) for i in range(n_links)
        ]
        self.u = [
            np.arange(n_links + i * per + 2 * n_elements, n_links + (i + 1) * per)
            for i in range(n_links)
        ]

    def tip(self, i: int) -> tuple[int, int, int]:
        """Indices of ``(w_N, theta_N, u_N)`` of link i."""
        return int(self.w[i][-2]), int(self.w[i][-1]), int(self.u[i][-1])

    def elimination_order(self) -> list[int]:
        """Interior nodes link by link (node-major), then joints and link tips (the border)."""
        order: list[int] = []
        for i in range(self.n):
            for k in range(self.N - 1):
                order += [int(self.w[i][2 * k]), int(self.w[i][2 * k + 1]), int(self.u[i][k])]
        order += list(range(self.n))
        for i in range(self.n):
            order += list(self.tip(i))
        return order


def _link_gram(lm: LinkMatrices, mass: float, inertia: float, qw, qu):
    """``G`` of ``T = 1/2 nu^T G nu``, ``nu = (v_bx, v_by, omega, q_w', q_u')`` (module doc)."""
    L, nw, nu = lm.length, lm.n_w, lm.n_u
    C = ca.DM(lm.C_wu)
    g_vx_om = -ca.dot(ca.DM(lm.s0w), qw)
    g_vy_om = 0.5 * mass * L + ca.dot(ca.DM(lm.s0u), qu)
    g_om_om = (
        inertia
        + 0.25 * mass * L * L
        + ca.bilin(ca.DM(lm.M_w), qw, qw)
        + 2.0 * ca.dot(ca.DM(lm.s1u), qu)
        + ca.bilin(ca.DM(lm.M_u), qu, qu)
    )
    g_om_w = ca.DM(lm.s1w) + ca.mtimes(C, qu)
    g_om_u = -ca.mtimes(C.T, qw)
    size = 3 + nw + nu
    G = ca.SX(size, size)
    G[0, 0] = mass
    G[1, 1] = mass
    G[0, 2] = G[2, 0] = g_vx_om
    G[1, 2] = G[2, 1] = g_vy_om
    G[2, 2] = g_om_om
    w_sl, u_sl = slice(3, 3 + nw), slice(3 + nw, size)
    G[1, w_sl] = ca.DM(lm.s0w).T
    G[w_sl, 1] = ca.DM(lm.s0w)
    G[0, u_sl] = ca.DM(lm.s0u).T
    G[u_sl, 0] = ca.DM(lm.s0u)
    G[2, w_sl] = g_om_w.T
    G[w_sl, 2] = g_om_w
    G[2, u_sl] = g_om_u.T
    G[u_sl, 2] = g_om_u
    G[w_sl, w_sl] = ca.sparsify(ca.DM(lm.M_w))
    G[u_sl, u_sl] = ca.sparsify(ca.DM(lm.M_u))
    return G


def _axial_energy(lm: LinkMatrices, EA: float, qw, qu, shortening: bool):
    """``1/2 sum_e EA l_e eps_e^2``, ``eps_e = u'_e (+ 1/2 mean_e w'^2)`` (module docstring)."""
    N = lm.n_elements
    le = lm.length / N
    Ge = ca.DM(lm.G_e)
    zero2 = ca.SX.zeros(2, 1)
    total = ca.SX(0)
    for j in range(N):
        u_left = qu[j - 1] if j > 0 else 0.0
        eps = (qu[j] - u_left) / le
        if shortening:
            qe = ca.vertcat(qw[2 * j - 2 : 2 * j] if j > 0 else zero2, qw[2 * j : 2 * j + 2])
            eps = eps + 0.5 * ca.bilin(Ge, qe, qe) / le
        total = total + 0.5 * EA * le * eps * eps
    return total


def _selection(indices: np.ndarray, size: int) -> ca.SX:
    S = ca.SX(len(indices), size)
    for r, c in enumerate(indices):
        S[r, int(c)] = 1
    return S


def _check(arm: ArmSpec, n_elements: int) -> None:
    if (
        isinstance(n_elements, bool)
        or not isinstance(n_elements, (int, np.integer))
        or not 1 <= n_elements <= MAX_ELEMENTS
    ):
        raise SpecError(
            f"value {n_elements!r} is not allowed; allowed: an integer from 1 to {MAX_ELEMENTS} "
            "(elements per link)",
            key="n_elements",
        )
    require_revolute(
        arm, "the finite-element arm", "prismatic joints: flexctrl.dynamics.fem.rp_arm"
    )


@dataclass(frozen=True)
class FemExpressions:
    """Symbolic pieces of the finite-element arm (SX in ``q``), before Lagrange's equations."""

    layout: _Layout
    mats: tuple[LinkMatrices, ...]
    EA: tuple[float, ...]
    q: ca.SX
    mass_matrix: ca.SX
    gravity_energy: ca.SX
    elastic_energy: ca.SX
    positions: ca.SX  # (2, n+1): joints, then the tip of the last link
    tip_deflection: ca.SX
    tip_slope: ca.SX

    def stiffness(self) -> np.ndarray:
        """``K`` at ``q = 0``: block diagonal of the links' ``K_w`` and ``K_u``."""
        lay = self.layout
        K = np.zeros((lay.size, lay.size))
        for i, lm in enumerate(self.mats):
            K[np.ix_(lay.w[i], lay.w[i])] = lm.K_w
            K[np.ix_(lay.u[i], lay.u[i])] = lm.K_u
        return K


def fem_expressions(arm: ArmSpec, n_elements: int, axial_shortening: bool = True) -> FemExpressions:
    """Kinematics, mass matrix and potential energies of the arm (see module docstring).

    Parameters
    ----------
    arm : ArmSpec
        The arm (revolute joints).
    n_elements : int
        Elements per link, 1..64.
    axial_shortening : bool
        The membrane strain ``u' + 1/2 w'^2`` instead of ``u'``.

    Returns
    -------
    FemExpressions
        SX expressions in the coordinates ``q``.
    """
    _check(arm, n_elements)
    n, N = arm.n_links, int(n_elements)
    lay = _Layout(n, N)
    nq = lay.size
    EA = tuple(link.axial_stiffness() for link in arm.links)
    mats = tuple(
        link_matrices(l.length, l.mass_per_length, l.EI, ea, N) for l, ea in zip(arm.links, EA)
    )
    gvec = ca.DM(np.asarray(arm.gravity, dtype=float).reshape(2, 1))
    q = ca.SX.sym("q", nq)
    M = ca.SX(nq, nq)
    U_g = ca.SX(0)
    r = ca.SX.zeros(2, 1)
    alpha_hat = ca.SX(0)
    positions, tip_w, tip_dw = [r], [], []
    U_el = ca.SX(0)
    for i, (link, joint, lm) in enumerate(zip(arm.links, arm.joints, mats)):
        qw, qu = q[lay.w[i]], q[lay.u[i]]
        alpha = alpha_hat + q[i]
        R = _rot(alpha)
        # hub i: point mass on the joint, rotor turning with link i
        M = _add_inertia(M, q, joint.hub_mass, r)
        M = _add_inertia(M, q, joint.hub_inertia, alpha)
        U_g -= joint.hub_mass * ca.dot(gvec, r)
        # link i in its frame: T = 1/2 nu^T G nu
        J_nu = ca.vertcat(
            ca.mtimes(R.T, ca.jacobian(r, q)),
            ca.jacobian(alpha, q),
            _selection(lay.w[i], nq),
            _selection(lay.u[i], nq),
        )
        G = _link_gram(lm, link.mass, link.inertia, qw, qu)
        M = M + ca.mtimes(J_nu.T, ca.mtimes(G, J_nu))
        first = ca.vertcat(
            0.5 * link.mass * link.length + ca.dot(ca.DM(lm.s0u), qu), ca.dot(ca.DM(lm.s0w), qw)
        )
        U_g -= ca.dot(gvec, link.mass * r + ca.mtimes(R, first))
        U_el += 0.5 * ca.bilin(ca.DM(lm.K_w), qw, qw) + _axial_energy(
            lm, EA[i], qw, qu, axial_shortening
        )
        # tip of link i: origin and orientation of the next frame
        w_N, th_N, u_N = (q[k] for k in lay.tip(i))
        r = r + ca.mtimes(R, ca.vertcat(link.length + u_N, w_N))
        positions.append(r)
        tip_w.append(w_N)
        tip_dw.append(th_N)
        alpha_hat = alpha + th_N
    M = _add_inertia(M, q, arm.payload.mass, r)
    M = _add_inertia(M, q, arm.payload.effective_inertia, alpha_hat)
    U_g -= arm.payload.mass * ca.dot(gvec, r)
    return FemExpressions(
        layout=lay,
        mats=mats,
        EA=EA,
        q=q,
        mass_matrix=M,
        gravity_energy=U_g,
        elastic_energy=U_el,
        positions=ca.horzcat(*positions),
        tip_deflection=ca.vertcat(*tip_w),
        tip_slope=ca.vertcat(*tip_dw),
    )


def _add_inertia(M: ca.SX, q: ca.SX, inertia: float, coordinate: ca.SX) -> ca.SX:
    """``M + m J^T J`` of a point mass at ``coordinate`` (m) or a rotor turning with it (rad)."""
    if inertia == 0.0:
        return M
    J = ca.jacobian(coordinate, q)
    return M + inertia * ca.mtimes(J.T, J)


def locked_matrices(arm: ArmSpec, n_elements: int, q_r: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """``(M_ff, K_ff)`` of the elastic dofs, the joints clamped at ``q_r``, the links straight.

    Cheaper than :func:`build_fem_model` (no dynamics are formed); the locked-joint
    natural frequencies are ``sqrt(eig(K_ff, M_ff))``.

    Parameters
    ----------
    arm : ArmSpec
        The arm.
    n_elements : int
        Elements per link.
    q_r : array_like
        Joint angles, rad.

    Returns
    -------
    M_ff, K_ff : ndarray
        Mass (kg, kg m, kg m^2) and stiffness (N/m, N, N m) of the elastic dofs.
    """
    ex = fem_expressions(arm, n_elements)
    n, nq = arm.n_links, ex.layout.size
    q0 = np.concatenate([np.asarray(q_r, dtype=float).reshape(n), np.zeros(nq - n)])
    M0 = np.array(ca.Function("M", [ex.q], [ex.mass_matrix])(q0))
    f = slice(n, nq)
    return 0.5 * (M0[f, f] + M0[f, f].T), ex.stiffness()[f, f]
