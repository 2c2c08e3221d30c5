"""Kinematics and energies of the planar assumed-modes arm (Subedi et al. 2021, Eqs 1-53).

Everything here is a CasADi expression in the generalised coordinates
``q = (q_r, q_f)`` and in the modal parameters of each link, which are either
numeric constants (frozen modes) or expressions in ``q`` from the lookup tables
(scheduled modes, see :mod:`flexctrl.dynamics.amm`).  The code is generic over
``casadi.SX`` and ``casadi.MX``.

Kinematics (Eqs 1-9)
    ``W_i = W_{i-1} E_{i-1} A_i`` with ``A_i`` the rotation by ``q_i`` and the
    paper's *linearised* tip rotation ``E_i = [[1, -w'_ie], [w'_ie, 1]]`` (Eq 7),
    kept as printed: ``W_i`` is then a rotation by ``alpha_i`` (Eq 8) times
    ``prod_k sqrt(1 + w'_ke^2)``, a second-order stretch of the outboard arm that is
    consistent with the small-deflection assumption.  ``p_i(x) = r_i + W_i (x, w_i(x))``,
    ``r_{i+1} = r_i + W_i (L_i, w_ie)`` (Eqs 3-4), ``r_1 = 0``.

Axial shortening (``axial_shortening=True``; ``docs/explanation/assumed-modes.md`` section 10)
    A bent link's points also move towards its root by ``s(x) = 1/2 int_0^x w'^2 =
    sum_p N_p(x) q_j q_k`` (mode pairs ``p = (j <= k)``, :mod:`flexctrl.modal.shortening`):
    ``p_i(x) = r_i + W_i (x - s(x), w_i(x))``, extra Gram pieces ``W_i e_1 q_j q_k`` with the
    integrals ``sh_*`` of :class:`LinkModal`, and the next frame turned by the exact rotation
    ``R(w'_ie)`` (``tip_rotation="exact"``; Eq 7's stretch is of the same order as ``s``).

Link kinetic energy (Eq 43) in closed form
    ``p_i(x) = sum_a N_a(x) P_a(q)`` with ``N = (1, x, phi_1, ..., phi_nf)`` and
    ``P = (r_i, W_i e_1, W_i e_2 q_f1, ..., W_i e_2 q_fnf)``, so
    ``int rho |p_i'|^2 dx = sum_ab G_ab Pdot_a . Pdot_b`` with the Gram matrix
    ``G = [[m, m L/2, v^T], [m L/2, J_l + m L^2/4, w^T], [v, w, z]]`` of Eqs 50-52
    (``int rho x^2 dx = J_l + m L^2/4`` from the file's centroidal inertia ``J_l``).
    ``M = sum J^T (G kron I_2) J`` with ``J = dP/dq``; hubs (Eq 42) and payload (Eq 44)
    add ``m J_r^T J_r + J (d alpha/dq)^T (d alpha/dq)``.

Shapes that move with the configuration (``shape_rates=True``)
    When the modal parameters are expressions in ``q`` (scheduled modes), the
    Jacobians above already see ``d phi_j(L)/dq`` and ``d phi'_j(L)/dq`` (hubs,
    payload, outboard frames), because the parameters enter *before* ``dP/dq``.
    The link's own mass also moves at ``n sum_jr psi_jr q_fj qd_r`` with
    ``psi_jr = d phi_j/d q_r`` and ``n = W e_2``: extra velocity pieces
    ``E_jr = n q_fj qd_r = (n q_fj e_r^T) qd``.  The link's kinetic energy is then the
    Gram form over the pieces ``(P, E)`` with the Gram matrix extended by
    ``int rho psi_jr = dv_j/dq_r`` and ``int rho x psi_jr = dw_j/dq_r`` (derivatives
    of the tables' v and w, so the terms they cancel cancel exactly),
    ``y[k, jr] = int rho phi_k psi_jr`` and ``s[jr, kt] = int rho psi_jr psi_kt``
    (tabulated, :mod:`flexctrl.modal.lookup`).  Without the ``E`` pieces the
    elastic equations keep ``(dv_j/dt)(n . rdot) + (dw_j/dt)(n . d(W e_1)/dt)``
    from ``d/dt(dT/d qd_f)``: a force on the modes that does not vanish at zero
    deflection (the shapes' change pushing on an undeformed link).  Keeping only
    the cross terms with the rigid velocity (first order in q_f) is not enough
    either: T is then not a sum of squares, and M loses definiteness at
    deflections of a few centimetres.  The full Gram form keeps M positive
    definite (the kinetic energy of a real velocity field).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import casadi as ca
import numpy as np

from flexctrl.beam.clamped_mass import ClampedMassModes
from flexctrl.modal.shortening import link_shortening, mode_pairs
from flexctrl.modal.static_correction import CorrectedModes
from flexctrl.spec.arm import ArmSpec, JointSpec, LinkSpec

#: A CasADi matrix: ``SX`` or ``MX`` built by the kinematics (the code is generic over both),
#: or ``DM`` for frozen modal constants.  CasADi's operators mix the three, which the overloads
#: of its type stubs cannot express for code generic over them.
Expression = Any

#: Modal fields per link, in packing order; ``z`` is (n_f, n_f), the others (n_f, 1).
MODAL_FIELDS = ("omega", "tip_deflection", "tip_slope", "v", "w", "z")


@dataclass(frozen=True)
class LinkModal:
    """Modal parameters of one link as CasADi column vectors / matrices (SX, MX or DM).

    The modes are mass-orthonormal to the link mass (Eq 40).

    Attributes
    ----------
    omega : Expression
        Natural frequencies (rad/s).
    tip_deflection, tip_slope : Expression
        ``phi(L)`` (dimensionless) and ``phi'(L)`` (1/m).
    v, w, z : Expression
        ``int rho phi dx`` (kg), ``int rho x phi dx`` (kg m), ``int rho phi_j phi_k dx`` (kg).
    shape_cross, shape_gram : Expression, optional
        Scheduled modes only: ``y[k, r n_f + j] = int rho phi_k dphi_j/dq_r`` (kg/rad) and
        ``s[r n_f + j, t n_f + k] = int rho dphi_j/dq_r dphi_k/dq_t`` (kg/rad^2).
    sh_tip, sh_v, sh_w, sh_y, sh_z : Expression, optional
        Axial shortening (:mod:`flexctrl.modal.shortening`): ``N_p(L)`` (P, 1) in 1/m,
        ``int rho N_p`` (P, 1) in kg/m, ``int rho x N_p`` (P, 1) in kg, ``int rho phi_l N_p``
        (n_f, P) in kg/m, ``int rho N_p N_p'`` (P, P) in kg/m^2.
    sh_psi : Expression, optional
        ``int rho dphi_j/dq_r N_p`` (n_f n, P) in kg/(m rad), scheduled modes only.
    """

    omega: Expression
    tip_deflection: Expression
    tip_slope: Expression
    v: Expression
    w: Expression
    z: Expression
    shape_cross: Expression = None
    shape_gram: Expression = None
    sh_tip: Expression = None
    sh_v: Expression = None
    sh_w: Expression = None
    sh_y: Expression = None
    sh_z: Expression = None
    sh_psi: Expression = None

    @property
    def n_modes(self) -> int:
        """Number of modes n_f."""
        return int(self.omega.shape[0]) if self.omega.numel() else 0

    @property
    def has_shortening(self) -> bool:
        """Whether the axial-shortening integrals are present."""
        return self.sh_v is not None and self.n_modes > 0

    @staticmethod
    def from_modes(modes: ClampedMassModes | CorrectedModes | None, n_modes: int) -> LinkModal:
        """Numeric constants from a link's modes (None if n_f = 0).

        The modes are :class:`~flexctrl.beam.clamped_mass.ClampedMassModes` or
        :class:`~flexctrl.modal.static_correction.CorrectedModes`; the axial-shortening
        integrals come from :func:`flexctrl.modal.shortening.link_shortening`.
        """
        if n_modes == 0 or modes is None:
            empty = ca.DM.zeros(0, 1)
            return LinkModal(empty, empty, empty, empty, empty, ca.DM.zeros(0, 0))
        fields = {
            name: ca.DM(
                np.reshape(
                    np.asarray(getattr(modes, name), dtype=float),
                    (n_modes, n_modes) if name == "z" else (n_modes, 1),
                )
            )
            for name in MODAL_FIELDS
        }
        short = link_shortening(modes)
        for name, value in short.items():
            fields[name] = ca.DM(value.reshape(-1, 1) if value.ndim == 1 else value)
        return LinkModal(**fields)


def _rotation(angle):
    c, s = ca.cos(angle), ca.sin(angle)
    return ca.vertcat(ca.horzcat(c, -s), ca.horzcat(s, c))


def _elastic_rotation(slope):
    """Eq 7: the linearised rotation by the tip slope, ``[[1, -w'], [w', 1]]``."""
    return ca.vertcat(ca.horzcat(1, -slope), ca.horzcat(slope, 1))


#: How the next link's frame turns with the tip slope ``w'``: Eq 7 as printed, or the rotation by
#: ``w'``.
TIP_ROTATIONS = ("linearized", "exact")


@dataclass(frozen=True)
class ArmExpressions:
    """Kinematic and energy expressions of the arm in ``q`` (and the modal parameters).

    Attributes
    ----------
    positions : expression (2, n+1)
        ``r_1 .. r_{n+1}``: joints in the world frame and, last, the tip of link n (m).
    tip_deflection, tip_slope : expression (n, 1)
        ``w_ie`` (m) and ``w'_ie`` (rad) of every link (Eq 2, Eq 7).
    orientations : expression (n+1, 1)
        ``alpha_1 .. alpha_n`` (Eq 8) and ``alpha-hat_{n+1}`` (Eq 9), rad.
    mass_matrix : expression (N, N)
        M(q).  Modal parameters given as expressions in ``q`` are differentiated with
        the kinematics; with ``shape_rates`` M holds the shapes' motion too (module docstring).
    gravity_energy, elastic_energy : scalar expressions
        U_g (Eqs 47-49) and U_el (Eq 46 with Eq 53), J.
    coriolis : expression (N, 1) or None
        ``c(q, qd)`` when ``qd`` was given; valid only for constant modal parameters.
    """

    positions: Expression
    tip_deflection: Expression
    tip_slope: Expression
    orientations: Expression
    mass_matrix: Expression
    gravity_energy: Expression
    elastic_energy: Expression
    coriolis: Expression = None


def flexible_offsets(n_links: int, n_modes: Sequence[int]) -> list[int]:
    """Index of the first elastic coordinate of each link in ``q`` (joints first).

    Parameters
    ----------
    n_links : int
        Number of links (and joints).
    n_modes : sequence of int
        Modes per link.

    Returns
    -------
    list of int
        One index per link.
    """
    offsets, k = [], n_links
    for nf in n_modes:
        offsets.append(k)
        k += nf
    return offsets


def stretched_links(n_modes: Sequence[int]) -> list[int]:
    """The links that ``axial_stretch`` makes axially compliant: those with elastic modes.

    Parameters
    ----------
    n_modes : sequence of int
        Modes per link.
    """
    return [i for i, nf in enumerate(n_modes) if nf > 0]


def coordinate_names(n_links: int, n_modes: Sequence[int]) -> tuple[str, ...]:
    """``q1..qn`` then ``qf11, qf12, ...`` (link, mode).

    Parameters
    ----------
    n_links : int
        Number of links (and joints).
    n_modes : sequence of int
        Modes per link.

    Returns
    -------
    tuple of str
        The coordinate names.
    """
    names = [f"q{i + 1}" for i in range(n_links)]
    for i, nf in enumerate(n_modes):
        names += [f"qf{i + 1}{j + 1}" for j in range(nf)]
    return tuple(names)


class _Inertia:
    """Accumulates ``M = sum J^T G J`` and, given ``qd``, ``c = sum J^T G (d/dt J) qd``.

    The second sum is the Coriolis vector for constant ``G`` and a true Jacobian
    ``J = dP/dq``: with ``T = 1/2 Pdot^T G Pdot``, Lagrange's equations give
    ``J^T G Pddot = J^T G (J qdd + Jdot qd)``.
    """

    def __init__(self, q, qd):
        self.q, self.qd = q, qd
        self.M = type(q).zeros(q.shape[0], q.shape[0])
        self.c = None if qd is None else type(q).zeros(q.shape[0], 1)

    def add(self, P, G) -> None:
        jac = ca.jacobian(P, self.q)
        self.M = self.M + ca.mtimes(jac.T, ca.mtimes(G, jac))
        if self.c is not None:
            accel = ca.jtimes(ca.mtimes(jac, self.qd), self.q, self.qd)
            self.c = self.c + ca.mtimes(jac.T, ca.mtimes(G, accel))

    def add_scalar(self, mass: float, P) -> None:
        if mass != 0.0:
            self.add(P, mass * ca.DM.eye(P.shape[0]))

    def add_moving_shapes(self, P, gram, md: LinkModal, qf, frame_y) -> None:
        """Add the link's Gram form over the pieces ``(P, E)`` (see the module docstring)."""
        if self.c is not None:
            raise ValueError(
                "moving shapes need the Lagrange form of the Coriolis vector (qd=None)"
            )
        N, nf = self.q.shape[0], qf.shape[0]
        n_rate = md.shape_gram.shape[0] // nf  # joints (columns r n_f + j)
        rows, cross = [], []
        dv, dw = ca.jacobian(md.v, self.q), ca.jacobian(md.w, self.q)
        for r in range(n_rate):
            unit = ca.DM.zeros(1, N)
            unit[0, r] = 1.0
            for j in range(nf):
                rows.append(ca.mtimes(frame_y * qf[j], unit))
                parts = [dv[j, r], dw[j, r], md.shape_cross[:, r * nf + j]]
                if gram.shape[0] > 2 + nf:  # axial-shortening pieces follow the modes
                    parts.append(md.sh_psi[r * nf + j, :].T)
                cross.append(ca.vertcat(*parts))
        jac = ca.vertcat(ca.jacobian(P, self.q), *rows)
        H = ca.horzcat(*cross)
        G = ca.blockcat([[gram, H], [H.T, 0.5 * (md.shape_gram + md.shape_gram.T)]])
        self.M = self.M + ca.mtimes(jac.T, ca.mtimes(ca.kron(G, ca.DM.eye(2)), jac))


def arm_expressions(
    arm: ArmSpec,
    modal: Sequence[LinkModal],
    q: Expression,
    qd: Expression = None,
    *,
    shape_rates: bool = False,
    axial_shortening: bool = False,
    tip_rotation: str = "linearized",
    axial_stretch: bool = False,
) -> ArmExpressions:
    """Kinematics, mass matrix and potential energies of ``arm`` in ``q``.

    Parameters
    ----------
    arm
        The arm; hubs, links and payload as in :mod:`flexctrl.spec.arm`.
    modal
        One :class:`LinkModal` per link (its ``n_modes`` sets the link's n_f).
    q
        Generalised coordinates, a column symbol of length ``n + sum n_f``.
    qd
        Their rates; when given, the Coriolis vector is formed body by body from
        the convective accelerations (only valid if ``modal`` holds constants).
    shape_rates
        ``modal`` holds expressions in ``q`` (scheduled modes) with ``shape_cross``
        and ``shape_gram``: the link velocities include the shapes' change with the
        configuration (module docstring).
    axial_shortening
        Points of a bent link move towards its root by ``s(x) = 1/2 int_0^x w'^2``
        (``modal`` must carry the ``sh_*`` integrals; module docstring).
    tip_rotation
        ``"linearized"`` (Eq 7) or ``"exact"`` (the next frame turned by ``w'_ie``).
    axial_stretch
        Axially compliant links: ``q`` ends with one elongation ``e_i`` (m) per link with
        elastic modes (:func:`stretched_links`; a link without modes stays rigid), a
        uniform strain ``e_i / L_i`` along the link (``docs/explanation/assumed-modes.md`` section
        14); the strain energy ``1/2 (EA_i / L_i) e_i^2`` is in
        :func:`flexctrl.dynamics.amm.build_amm`'s ``K``.
    """
    n = arm.n_links
    n_modes = [m.n_modes for m in modal]
    offsets = flexible_offsets(n, n_modes)
    stretched = stretched_links(n_modes) if axial_stretch else []
    stretch_index = {i: q.shape[0] - len(stretched) + k for k, i in enumerate(stretched)}
    gravity = ca.DM(np.asarray(arm.gravity, dtype=float).reshape(2, 1))
    sym = type(q)
    inertia = _Inertia(q, qd)
    walk = _Walk(sym)
    for i, (link, joint, md) in enumerate(zip(arm.links, arm.joints, modal)):
        nf = md.n_modes
        qf = q[offsets[i] : offsets[i] + nf] if nf else sym.zeros(0, 1)
        W = ca.mtimes(walk.W_hat, _rotation(q[i]))  # Eq 5
        alpha = walk.alpha_hat + q[i]  # Eq 8
        walk.orientations.append(alpha)
        _add_hub(walk, inertia, joint, gravity, alpha)
        # uniform strain: the point at x sits at x (1 + e / L) along the link (flexible links only)
        stretch = 1 + q[stretch_index[i]] / link.length if i in stretch_index else 1
        link_frame = _LinkFrame(W, qf, stretch, axial_shortening and nf > 0)
        _add_link(walk, inertia, link, md, link_frame, gravity, shape_rates)
        _to_tip(walk, md, link_frame, link.length, alpha, tip_rotation)
    walk.orientations.append(walk.alpha_hat)
    # payload (Eqs 44, 49): mass at r_{n+1}, inertia turning with alpha-hat_{n+1}
    inertia.add_scalar(arm.payload.mass, walk.r)
    inertia.add_scalar(arm.payload.effective_inertia, walk.alpha_hat)
    walk.U_g = walk.U_g - arm.payload.mass * ca.dot(gravity, walk.r)
    return ArmExpressions(
        positions=ca.horzcat(*walk.positions),
        tip_deflection=ca.vertcat(*walk.deflections),
        tip_slope=ca.vertcat(*walk.slopes),
        orientations=ca.vertcat(*walk.orientations),
        mass_matrix=inertia.M,
        coriolis=inertia.c,
        gravity_energy=walk.U_g,
        elastic_energy=walk.U_el,
    )


@dataclass
class _Walk:
    """The state of the walk from the base out, link by link (Eqs 2-9)."""

    sym: type
    r: Expression = None
    W_hat: Expression = None  # \hat W_{i-1} = W_{i-1} E_{i-1}
    alpha_hat: Expression = None  # \hat alpha_i (Eq 9)
    U_g: Expression = None
    U_el: Expression = None
    positions: list[Expression] = field(default_factory=list)
    deflections: list[Expression] = field(default_factory=list)
    slopes: list[Expression] = field(default_factory=list)
    orientations: list[Expression] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.U_g = self.sym(0)
        self.U_el = self.sym(0)
        self.r = self.sym(ca.DM.zeros(2, 1))
        self.W_hat = self.sym(ca.DM.eye(2))
        self.alpha_hat = self.sym(0)
        self.positions.append(self.r)


@dataclass(frozen=True)
class _LinkFrame:
    """Link i's frame ``W``, its elastic coordinates and what its kinematics include."""

    W: Expression
    qf: Expression
    stretch: Expression  # 1, or 1 + e_i / L_i
    shortening: bool
    sigma: list[Expression] = field(default_factory=list)  # q_j q_k of the mode pairs

    @cached_property
    def x(self) -> Expression:
        """``W e_1``: along the link."""
        return ca.mtimes(self.W, ca.DM([1.0, 0.0]))

    @cached_property
    def y(self) -> Expression:
        """``W e_2``: across the link."""
        return ca.mtimes(self.W, ca.DM([0.0, 1.0]))


def _add_hub(
    walk: _Walk, inertia: _Inertia, joint: JointSpec, gravity: ca.DM, alpha: Expression
) -> None:
    """Hub i (Eqs 42, 47): a point mass at ``r_i``, a rotor inertia turning with ``alpha_i``."""
    inertia.add_scalar(joint.hub_mass, walk.r)
    inertia.add_scalar(joint.hub_inertia, alpha)
    walk.U_g = walk.U_g - joint.hub_mass * ca.dot(gravity, walk.r)


def _add_link(
    walk: _Walk,
    inertia: _Inertia,
    link: LinkSpec,
    md: LinkModal,
    frame: _LinkFrame,
    gravity: ca.DM,
    shape_rates: bool,
) -> None:
    """Link i's mass (Eqs 43, 48): generalised positions ``P_a``, their Gram matrix, energies."""
    sym, qf, nf = walk.sym, frame.qf, md.n_modes
    m, length = link.mass, link.length
    frame_x, frame_y = frame.x, frame.y
    pieces = [walk.r, frame_x * frame.stretch] + [frame_y * qf[j] for j in range(nf)]
    rigid = ca.DM([[m, 0.5 * m * length], [0.5 * m * length, link.inertia + 0.25 * m * length**2]])
    moments = sym(ca.horzcat(md.v, md.w))
    gram = ca.blockcat([[sym(rigid), moments.T], [moments, sym(0.5 * (md.z + md.z.T))]])
    if frame.shortening:  # s(x) = sum_p N_p(x) q_j q_k along -W e_1: pieces W e_1 sigma_p
        if not md.has_shortening:
            raise ValueError(
                "axial_shortening needs the modes' shortening integrals (LinkModal.sh_*)"
            )
        frame.sigma.extend(qf[j] * qf[k] for j, k in mode_pairs(nf))
        pieces += [frame_x * s_p for s_p in frame.sigma]
        edge = sym(ca.vertcat(md.sh_v.T, md.sh_w.T, md.sh_y))
        gram = ca.blockcat([[gram, edge], [edge.T, sym(0.5 * (md.sh_z + md.sh_z.T))]])
    P = ca.vertcat(*pieces)
    if shape_rates and nf and md.shape_gram is not None and md.shape_gram.shape[0]:
        inertia.add_moving_shapes(P, gram, md, qf, frame_y)
    else:
        inertia.add(P, ca.kron(gram, ca.DM.eye(2)))
    first_moment = m * walk.r + 0.5 * m * length * frame_x * frame.stretch
    if nf:
        first_moment = first_moment + frame_y * ca.dot(md.v, qf)
    if frame.shortening:
        first_moment = first_moment + frame_x * ca.dot(md.sh_v, ca.vertcat(*frame.sigma))
    walk.U_g = walk.U_g - ca.dot(gravity, first_moment)
    if nf:
        walk.U_el = walk.U_el + 0.5 * link.mass * ca.sumsqr(md.omega * qf)  # Eqs 46, 53


def _to_tip(
    walk: _Walk,
    md: LinkModal,
    frame: _LinkFrame,
    length: float,
    alpha: Expression,
    tip_rotation: str,
) -> None:
    """Move the walk to the tip of link i (Eqs 2, 4, 7, 9): its position, deflection, frame."""
    nf, qf, W = md.n_modes, frame.qf, frame.W
    w_e = ca.dot(md.tip_deflection, qf) if nf else walk.sym(0)
    dw_e = ca.dot(md.tip_slope, qf) if nf else walk.sym(0)
    walk.deflections.append(w_e)
    walk.slopes.append(dw_e)
    walk.r = walk.r + ca.mtimes(W, ca.vertcat(length * frame.stretch, w_e))
    if frame.shortening:
        walk.r = walk.r + frame.x * ca.dot(md.sh_tip, ca.vertcat(*frame.sigma))
    walk.positions.append(walk.r)
    turn = _rotation(dw_e) if tip_rotation == "exact" else _elastic_rotation(dw_e)
    walk.W_hat = ca.mtimes(W, turn) if nf else W
    walk.alpha_hat = alpha + dw_e
