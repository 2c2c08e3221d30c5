"""Assumed-modes model of a planar flexible arm (Subedi et al. 2021), for n >= 1 links.

Built symbolically in CasADi SX from the Lagrangian ``L = T - U_g - U_el``
(kinematics and energies in :mod:`flexctrl.dynamics.amm_kinematics`):

* ``M(q) = d^2 T / d qd^2`` (T is exactly quadratic in qd; M is formed as
  ``sum J^T G J`` over the bodies, see the kinematics module);
* ``c(q, qd) = (d(M qd)/dq) qd - dT/dq`` (equal to Eq 62's Christoffel form); for
  frozen modes it is formed body by body as ``sum J^T G (dJ/dt) qd`` (same value,
  about a sixth of the code; ``coriolis="lagrange"`` selects the generic form);
* ``g(q) = dU_g/dq`` (Eq 63) and ``K = diag(0, m_l omega^2)`` (Eqs 64-66);
* ``D = diag(b, d)`` (Eqs 67-68), joint friction ``b`` from the file;
* ``M qdd + c + g + K q + D qd = B tau``, ``B = [I_n; 0]``, solved for qdd by an
  explicit symbolic LDL^T factorisation (no square roots, no pivoting: M is
  symmetric positive definite), which generates smaller and faster code than
  ``casadi.solve`` (symbolic QR) for these sizes.

Modal damping
    Eq 68 prints ``d = 2 zeta sqrt(k/m_l) = 2 zeta omega``.  With the modes
    normalised to the link mass (Eq 40) the modal mass is ``m_l``, so that
    coefficient gives a damping ratio of ``zeta / m_l`` (and the wrong unit,
    1/s instead of kg/s).  ``damping="ratio"`` (default) uses
    ``d = 2 zeta omega m_l``, which makes ``zeta`` the damping ratio of the isolated
    mode as the file's ``damping_ratio`` says; ``damping="paper"`` uses Eq 68 as printed;
    ``damping="stiffness"`` the finite elements' stiffness-proportional rule
    ``(2 zeta_1 / omega_1) m_l omega_j^2`` (mode j's ratio ``zeta_1 omega_j / omega_1``).
    The default (None) is the arm's ``damping_form`` (model file key ``damping_form``,
    scene key ``[damping] form``).

Frozen and scheduled modes
    ``modes="frozen"``: the clamped-mass modes of each link are computed once, at
    ``reference_q`` (default: the arm's ``configuration``) with the arm's payload;
    all modal parameters are constants.

    ``modes="scheduled"``: the modal parameters ``p = (omega, phi(L), phi'(L), v, w, z)``
    of each link follow the configuration through the differentiable lookup
    (:func:`flexctrl.modal.lookup.modal_lookup`) and are put *into the kinematics*
    before anything is differentiated: the deflection field is
    ``w_i(x) = sum_j phi_j(x; q_r) q_fj``, so hubs, payload and outboard frames move
    with ``d phi_j(L)/dt`` too, and the link's own mass with ``d phi_j(x)/dt``, whose
    kinetic energy is kept in full through the tables' shape-rate integrals
    (:mod:`flexctrl.dynamics.amm_kinematics`, "Shapes that move with the
    configuration").  ``U = U_g(q, p(q_r)) + 1/2 sum m_l omega(q_r)^2 q_f^2`` is exact
    for mass-orthonormal clamped-mass modes (``int EI phi_j'' phi_k'' = m_l omega_j^2
    delta_jk``).  The equations come from that Lagrangian with every q-derivative
    (including ``dp/dq_r``) taken, so the model conserves ``T + U`` without damping.
    The approximations left are the assumed-modes truncation and the interpolation
    of the tables.

    The shape rates stay in T.  Forming T with the shapes held still (``phi_j qd_fj``
    only) drops a term of the *same* order as the one it keeps: ``d/dt (dT/d qd_f)``
    then holds ``(dv_j/dt)(n . rdot) + (dw_j/dt) alpha-dot``, a force on the modes that
    does not vanish at zero deflection and drives them in a free swing
    (``test_scheduled_inertial_load_equals_frozen_at_rest_deflection`` guards it).
    Keeping only the rigid-velocity cross terms of the shape rate is not enough either:
    M then loses definiteness at a few centimetres of deflection.

    Interface: ``K`` and ``D`` take ``q``; ``g`` holds every potential force not in
    ``K q``, i.e. ``g = dU_g/dq + dU_el/dq - K(q) q`` (the second part is
    ``1/2 q_f^T (dK/dq_r) q_f`` on the joint rows).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from typing import Literal

import casadi as ca
import numpy as np
import scipy.linalg

from flexctrl.dynamics.amm_kinematics import (
    TIP_ROTATIONS,
    LinkModal,
    arm_expressions,
    coordinate_names,
    flexible_offsets,
    stretched_links,
)
from flexctrl.dynamics.model import Model
from flexctrl.errors import SpecError
from flexctrl.spec.arm import DAMPING_FORMS, ArmSpec
from flexctrl.spec.fidelity import Fidelity

MODES = ("frozen", "scheduled")
DAMPING = DAMPING_FORMS
SOLVERS = ("ldl", "qr")
CORIOLIS = ("bodies", "lagrange")


def ldl_solve(A, b):
    """Solve ``A x = b`` for symmetric positive definite ``A`` by an explicit LDL^T (symbolic).

    Structural zeros of ``A`` are skipped.  No pivoting: only for matrices known to be
    positive definite (mass matrices).  One division per pivot.
    """
    n = A.shape[0]
    if n == 0:
        return type(A).zeros(0, 1)
    L = [[None] * n for _ in range(n)]  # unit lower factor
    a = [[None] * n for _ in range(n)]  # a[j][k] = L[j][k] d[k]
    inv_d = [None] * n

    def dot(row_a, row_l, stop):
        terms = [
            row_a[m] * row_l[m]
            for m in range(stop)
            if row_a[m] is not None and row_l[m] is not None
        ]
        return sum(terms[1:], terms[0]) if terms else None

    def minus(x, y):
        if y is None:
            return x
        return -y if x is None else x - y

    for j in range(n):
        for k in range(j):
            s = minus(None if A[j, k].is_zero() else A[j, k], dot(a[j], L[k], k))
            if s is not None:
                a[j][k], L[j][k] = s, s * inv_d[k]
        inv_d[j] = 1 / minus(A[j, j], dot(a[j], L[j], j))
    y = [None] * n
    for i in range(n):  # L y = b
        s = b[i]
        for k in range(i):
            if L[i][k] is not None:
                s = s - L[i][k] * y[k]
        y[i] = s
    x = [None] * n
    for i in reversed(range(n)):  # L^T x = D^-1 y
        s = y[i] * inv_d[i]
        for k in range(i + 1, n):
            if L[k][i] is not None:
                s = s - L[k][i] * x[k]
        x[i] = s
    return ca.vertcat(*x)


def natural_frequencies(K: np.ndarray, M: np.ndarray) -> np.ndarray:
    """Undamped natural frequencies (rad/s, ascending) of ``M qdd + K q = 0``: ``sqrt`` of the eigenvalues of ``K v = lambda M v``.

    ``M`` symmetric positive definite; only the lower triangles are read (``scipy.linalg.eigh``),
    so pass ``0.5 (A + A^T)`` for a matrix that is symmetric only to rounding when both
    triangles should count.  Negative eigenvalues are clipped to 0, with a RuntimeWarning
    when they exceed rounding (``1e-9`` of the largest).
    """
    lam = scipy.linalg.eigh(K, M, eigvals_only=True)
    if np.any(lam < -1e-9 * max(1.0, float(np.max(np.abs(lam), initial=0.0)))):
        warnings.warn(
            f"the structure has negative stiffness eigenvalues {lam[lam < 0]}; clipped to 0",
            RuntimeWarning,
            stacklevel=3,
        )
    return np.sqrt(np.clip(lam, 0.0, None))


def locked_spectrum(M: np.ndarray, K: np.ndarray, n_joints: int) -> np.ndarray:
    """Natural frequencies (rad/s, ascending) with the joints clamped: ``K_ff`` against ``M_ff``.

    ``M`` and ``K`` are the whole model's (N x N); the elastic block is the one after the
    ``n_joints`` joint coordinates.  The one copy of this spectrum: the model's
    ``info["locked_frequencies_rad_s"]`` and :func:`flexctrl.linear.locked_frequencies`.
    """
    if M.shape[0] == n_joints:
        return np.zeros(0)
    flex = slice(n_joints, None)
    return natural_frequencies(K[flex, flex], M[flex, flex])


def _check_choice(value: str, allowed: tuple[str, ...], key: str) -> str:
    if value not in allowed:
        raise SpecError(
            f"value {value!r} is not allowed; allowed: {', '.join(repr(a) for a in allowed)}",
            key=key,
        )
    return value


def _frozen_modal(
    arm: ArmSpec, q_ref: np.ndarray, n_modes: Sequence[int], correct: Sequence[bool] = ()
):
    """Frozen modal constants per link; links flagged in ``correct`` get the tip-moment correction shape last."""
    from flexctrl.modal.arm_modes import link_modes
    from flexctrl.modal.static_correction import CorrectedModes

    modal, freqs = [], []
    for i, nf in enumerate(n_modes):
        modes = link_modes(arm, q_ref, i, nf) if nf else None
        if nf and i < len(correct) and correct[i]:
            modes = CorrectedModes(modes)
        modal.append(LinkModal.from_modes(modes, modes.n_modes if nf else 0))
        freqs.append([float(x) for x in np.asarray(modes.omega)] if nf else [])
    return modal, freqs


def _scheduled_modal(arm: ArmSpec, q, n_modes: Sequence[int], lookups):
    """Modal expressions p(q_r) from the lookup functions (one per link, None for n_f = 0).

    The tables enter as their second-order expansion about a symbolic point ``q0``,
    ``p(q) = a + B (q - q0) + 1/2 (q - q0)^T C (q - q0)``, with ``a, B, C`` symbols.
    The equations of motion need at most second derivatives of ``p``, which this
    expansion gives exactly at ``q = q0``.  Returns the modal parameters and the
    substitution ``(symbols, values)`` that puts ``q0 = q`` and the spline's value,
    Jacobian and Hessian in place: one spline evaluation of each order per link,
    instead of one per place CasADi differentiates a spline call (85 of them in ``f``
    for three links), which made ``f`` about five times slower.  Derivatives of the
    substituted expressions (linearisation) go through the spline calls and stay exact.
    """
    if lookups is None:
        from flexctrl.modal.lookup import modal_lookup

        lookups = [
            modal_lookup(arm, i, nf).function if nf else None for i, nf in enumerate(n_modes)
        ]
    n = arm.n_links
    q0 = ca.SX.sym("q_expansion", n)
    step = q[:n] - q0
    symbols, values = [q0], [q[:n]]
    modal = []
    for i, nf in enumerate(n_modes):
        if nf == 0:
            modal.append(LinkModal.from_modes(None, 0))
            continue
        point = ca.SX.sym("q_table", n)
        outputs = lookups[i](point)  # in LinkModal's field order: FIELDS, then y, s
        shapes = [out.shape for out in outputs]
        value = ca.vertcat(*(ca.vec(out) for out in outputs))
        m = value.shape[0]
        jac = ca.jacobian(value, point)
        hess = ca.jacobian(ca.vec(jac), point)  # row i + m k: d^2 value_i / dq_k dq
        derivatives = ca.Function(f"modal_expansion_link{i + 1}", [point], [value, jac, hess])
        a, B, C = (
            ca.SX.sym(f"a{i + 1}", m),
            ca.SX.sym(f"B{i + 1}", m, n),
            ca.SX.sym(f"C{i + 1}", m * n, n),
        )
        local = a + ca.mtimes(B, step) + 0.5 * ca.mtimes(ca.reshape(ca.mtimes(C, step), m, n), step)
        symbols += [a, B, C]
        values += [ca.densify(v) for v in derivatives(q[:n])]
        pieces, offset = [], 0
        for shape in shapes:
            size = shape[0] * shape[1]
            pieces.append(ca.reshape(local[offset : offset + size], shape[0], shape[1]))
            offset += size
        modal.append(LinkModal(*pieces))
    return modal, (symbols, values)


#: The assumed-modes default of ``axial_shortening`` when neither the call, the scene nor the
#: model file sets it: off.  The effect is correct physics (docs/amm.md section 12), but the
#: shipped controllers, tunings and studies are tuned on the model without it, and the
#: compiled step costs more with it.  Turn it on per model file or scene
#: (``axial_shortening = true``).
AMM_AXIAL_SHORTENING = False

#: The default of ``axial_stretch``: off (``docs/amm.md`` section 14).
AMM_AXIAL_STRETCH = False

#: The default of ``static_correction``: off (``docs/amm.md`` section 13).
AMM_STATIC_CORRECTION = False


def build_amm(
    arm: ArmSpec,
    n_modes: int | Sequence[int],
    *,
    modes: Literal["frozen", "scheduled"] = "frozen",
    reference_q: Sequence[float] | None = None,
    damping: Literal["ratio", "paper", "stiffness"] | None = None,
    solver: Literal["ldl", "qr"] = "ldl",
    fidelity: Fidelity | None = None,
    lookups: Sequence[ca.Function | None] | None = None,
    coriolis: Literal["bodies", "lagrange"] = "bodies",
    axial_shortening: bool | None = None,
    tip_rotation: Literal["linearized", "exact"] | None = None,
    static_correction: bool | None = None,
    axial_stretch: bool | None = None,
) -> Model:
    """Build the assumed-modes model of ``arm``.

    Parameters
    ----------
    arm
        The arm (payload included).
    n_modes
        Modes per link (one number for every link, or one per link), 0..6.
    modes
        ``"frozen"`` (modes at ``reference_q``) or ``"scheduled"`` (modal parameters
        looked up from the configuration; see the module docstring).
    reference_q
        Joint angles (rad) of the frozen modes and of ``omega_max``; default the
        arm's ``configuration``.
    damping
        ``"ratio"`` (d = 2 zeta omega m_l) or ``"paper"`` (Eq 68 as printed, 2 zeta omega);
        None: the arm's ``damping_form``.
    solver
        Symbolic solve of ``M qdd = rhs`` in ``f``: ``"ldl"`` (explicit LDL^T) or
        ``"qr"`` (``casadi.solve``).
    fidelity
        Recorded in the model (default ``amm:N`` when all links have N modes).
    coriolis
        How ``c`` is formed for frozen modes: ``"bodies"`` (``sum J^T G Jdot qd`` over
        the bodies, smaller code) or ``"lagrange"`` (``d(M qd)/dq qd - dT/dq``, the
        form always used for scheduled modes).  Both are exact.
    axial_shortening
        Second-order (foreshortening) kinematics: a bent link's points move towards its
        root by ``1/2 int_0^x w'^2`` (``docs/amm.md`` section 10).  Default: the arm's
        ``axial_shortening`` (model file or scene key), else :data:`AMM_AXIAL_SHORTENING`.
    tip_rotation
        ``"linearized"`` (Eq 7 as printed) or ``"exact"`` (the next link's frame turned by
        the tip slope).  Default: ``"exact"`` with axial shortening (the second-order
        kinematics are consistent only then), ``"linearized"`` without.
    axial_stretch
        Axially compliant links: one elongation ``e_i`` (m) per link with elastic modes
        appended to ``q`` (names ``e1..en``; a link without modes, hence ``rigid``, stays
        rigid), a uniform strain ``e_i / L_i`` with strain energy
        ``1/2 (EA_i / L_i) e_i^2`` and the finite elements' damping rule
        ``(2 zeta_i / omega_1i) EA_i / L_i`` (``docs/amm.md`` section 14).  Frozen modes
        only.  Default: the arm's ``axial_stretch``, else :data:`AMM_AXIAL_STRETCH`.
    lookups
        For ``"scheduled"``: one CasADi Function per link with the signature of
        :attr:`flexctrl.modal.lookup.ModalLookup.function` (None for links without
        modes); default: built by :func:`~flexctrl.modal.lookup.modal_lookup`.

    Returns
    -------
    Model
        Functions ``M, c, g, K, D, f, energies, tip, hubs, deflection``
        (see :mod:`flexctrl.dynamics.model`).
    """
    start = time.perf_counter()
    _check_choice(modes, MODES, "modes")
    damping = arm.damping_form if damping is None else damping
    _check_choice(damping, DAMPING, "damping")
    _check_choice(solver, SOLVERS, "solver")
    _check_choice(coriolis, CORIOLIS, "coriolis")
    if axial_shortening is None:
        axial_shortening = (
            AMM_AXIAL_SHORTENING if arm.axial_shortening is None else arm.axial_shortening
        )
    shortening = bool(axial_shortening)
    rotation = _check_choice(
        tip_rotation or ("exact" if shortening else "linearized"), TIP_ROTATIONS, "tip_rotation"
    )
    n = arm.n_links
    n_modes = [int(n_modes)] * n if np.isscalar(n_modes) else [int(k) for k in n_modes]
    if len(n_modes) != n or any(not 0 <= k <= 6 for k in n_modes):
        raise SpecError(
            f"n_modes {n_modes!r} is not allowed; allowed: one count 0..6 or one per link ({n} links)",
            key="n_modes",
        )
    q_ref = arm.configuration_or_default(reference_q)
    if fidelity is None:
        fidelity = Fidelity("amm", n_modes[0]) if len(set(n_modes)) == 1 else Fidelity("amm")
    correction = AMM_STATIC_CORRECTION if static_correction is None else bool(static_correction)
    corrected = [correction and i < n - 1 and nf > 0 for i, nf in enumerate(n_modes)]
    if any(corrected) and modes == "scheduled":
        raise SpecError(
            "value True is not allowed with modes='scheduled'; allowed: static_correction with frozen modes",
            key="static_correction",
        )
    frozen_modal, link_freqs = _frozen_modal(arm, q_ref, n_modes, corrected)
    n_modes = [md.n_modes for md in frozen_modal]
    if axial_stretch is None:
        axial_stretch = AMM_AXIAL_STRETCH if arm.axial_stretch is None else arm.axial_stretch
    stretch = bool(axial_stretch)
    if stretch and modes == "scheduled":
        raise SpecError(
            "value True is not allowed with modes='scheduled'; allowed: axial_stretch with frozen modes",
            key="axial_stretch",
        )
    stretched = stretched_links(n_modes) if stretch else []
    names = coordinate_names(n, n_modes) + tuple(f"e{i + 1}" for i in stretched)
    N = len(names)
    offsets = flexible_offsets(n, n_modes)
    flex = np.arange(n, N)

    q, qd, u = ca.SX.sym("q", N), ca.SX.sym("qd", N), ca.SX.sym("u", n)
    scheduled = modes == "scheduled" and N > n
    if scheduled:
        modal, expansion = _scheduled_modal(arm, q, n_modes, lookups)
        ex = arm_expressions(
            arm, modal, q, shape_rates=True, axial_shortening=shortening, tip_rotation=rotation
        )
    else:
        modal = frozen_modal
        ex = arm_expressions(
            arm,
            modal,
            q,
            qd if coriolis == "bodies" else None,
            axial_shortening=shortening,
            tip_rotation=rotation,
            axial_stretch=stretch,
        )

    # stiffness and damping (Eqs 65-68)
    stiffness, damp = [ca.SX(0)] * n, [ca.SX(arm.joints[i].friction) for i in range(n)]
    for i, (link, md) in enumerate(zip(arm.links, modal)):
        for j in range(n_modes[i]):
            omega = md.omega[j]
            stiffness.append(link.mass * omega**2)
            if (
                damping == "stiffness"
            ):  # the finite elements' (2 zeta / omega_1) K on the modal stiffness
                damp.append(2.0 * link.damping_ratio(0) / float(md.omega[0]) * link.mass * omega**2)
            else:
                scale = link.mass if damping == "ratio" else 1.0
                damp.append(2.0 * link.damping_ratio(j) * omega * scale)
    E_el = ex.elastic_energy
    if (
        stretch
    ):  # elongations e_i: strain energy 1/2 (EA / L) e^2, damped as the finite elements' links
        for i in stretched:
            link, md = arm.links[i], modal[i]
            k_axial = link.axial_stiffness() / link.length
            stiffness.append(ca.SX(k_axial))
            E_el = E_el + 0.5 * k_axial * q[names.index(f"e{i + 1}")] ** 2
            # stiffness-proportional, (2 zeta / omega_1) k with omega_1 the link's first clamped-mass mode
            damp.append(ca.SX(2.0 * link.damping_ratio(0) / float(md.omega[0]) * k_axial))
    K = ca.diag(ca.vertcat(*stiffness))
    D = ca.diag(ca.vertcat(*damp))

    # Lagrange's equations
    M = ex.mass_matrix
    Mqd = ca.mtimes(M, qd)
    E_kin = 0.5 * ca.dot(qd, Mqd)
    if ex.coriolis is not None:
        c = ex.coriolis
    else:
        c = ca.jtimes(Mqd, q, qd) - ca.gradient(E_kin, q)
    g = ca.gradient(ex.gravity_energy, q)
    if scheduled:
        g = g + ca.gradient(ex.elastic_energy, q) - ca.mtimes(K, q)
    B = ca.vertcat(ca.SX.eye(n), ca.SX.zeros(N - n, n))
    rhs = ca.mtimes(B, u) - c - g - ca.mtimes(K, q) - ca.mtimes(D, qd)
    qdd = ldl_solve(M, rhs) if solver == "ldl" else ca.solve(M, rhs)
    x = ca.vertcat(q, qd)

    opts = {"cse": True}
    tip = ex.positions[:, n]
    expr = {
        "M": M,
        "c": c,
        "g": g,
        "K": K,
        "D": D,
        "xdot": ca.vertcat(qd, qdd),
        "E_kin": E_kin,
        "E_el": E_el,
        "E_grav": ex.gravity_energy,
        "tip": tip,
        "tip_v": ca.jtimes(tip, q, qd),
        "hubs": ex.positions,
        "w": ex.tip_deflection,
        "dw": ex.tip_slope,
    }
    if scheduled:  # the tables' expansion point is the current configuration (see _scheduled_modal)
        expr = dict(zip(expr, ca.substitute(list(expr.values()), *expansion)))
    functions = {
        "M": ca.Function("M", [q], [expr["M"]], ["q"], ["M"], opts),
        "c": ca.Function("c", [q, qd], [expr["c"]], ["q", "qd"], ["c"], opts),
        "g": ca.Function("g", [q], [expr["g"]], ["q"], ["g"], opts),
        "K": ca.Function("K", [q], [expr["K"]], ["q"], ["K"], opts)
        if scheduled
        else ca.Function("K", [], [K], [], ["K"]),
        "D": ca.Function("D", [q], [expr["D"]], ["q"], ["D"], opts)
        if scheduled
        else ca.Function("D", [], [D], [], ["D"]),
        "f": ca.Function("f", [x, u], [expr["xdot"]], ["x", "u"], ["xdot"], opts),
        "energies": ca.Function(
            "energies",
            [q, qd],
            [expr["E_kin"], expr["E_el"], expr["E_grav"]],
            ["q", "qd"],
            ["E_kin", "E_el", "E_grav"],
            opts,
        ),
        "tip": ca.Function(
            "tip", [q, qd], [expr["tip"], expr["tip_v"]], ["q", "qd"], ["p", "v"], opts
        ),
        "hubs": ca.Function("hubs", [q], [expr["hubs"]], ["q"], ["p"], opts),
        "deflection": ca.Function(
            "deflection", [q], [expr["w"], expr["dw"]], ["q"], ["w", "dw"], opts
        ),
    }

    # locked-joint linearisation at the reference configuration (joints clamped, q_f = 0, qd = 0)
    q0 = np.concatenate([q_ref, np.zeros(N - n)])
    locked, free = np.zeros(0), np.zeros(0)
    if N > n:
        M0 = np.array(functions["M"](q0))
        K0 = np.array(functions["K"](q0) if scheduled else functions["K"]()["K"])
        locked = locked_spectrum(M0, K0, n)
        # free joints (no gravity): the elastic coordinates see the Schur complement of M
        schur = M0[np.ix_(flex, flex)] - M0[n:, :n] @ np.linalg.solve(M0[:n, :n], M0[:n, n:])
        free = natural_frequencies(K0[np.ix_(flex, flex)], 0.5 * (schur + schur.T))
    info = {
        "family": "amm",
        "modes": "scheduled" if scheduled else "frozen",
        "modes_requested": modes,
        "n_modes": list(n_modes),
        "flexible_offsets": offsets,
        "reference_q": q_ref.tolist(),
        "link_frequencies_rad_s": link_freqs,
        "locked_frequencies_rad_s": locked.tolist(),
        "free_frequencies_rad_s": free.tolist(),
        "damping": damping,
        "solver": solver,
        "coriolis": "lagrange" if scheduled else coriolis,
        "axial_shortening": shortening,
        "axial_stretch": stretch,
        "static_correction": [bool(c) for c in corrected],
        "elastic_rotation": "linearised E_i = [[1, -w'], [w', 1]] (Eq 7)"
        if rotation == "linearized"
        else "exact rotation by the tip slope w'_ie",
        "g_convention": "dU_g/dq + dU_el/dq - K(q) q" if scheduled else "dU_g/dq",
        "input_matrix": "tau acts on q1..qn",
        "build_time_s": time.perf_counter() - start,
    }
    return Model(
        name=f"{arm.name} amm {'/'.join(map(str, n_modes))} {info['modes']}{'' if shortening else ' no-shortening'}{' static-correction' if any(corrected) else ''}{' axial-stretch' if stretch else ''}"
        f"{'' if rotation == ('exact' if shortening else 'linearized') else ' ' + rotation + '-rotation'}",
        fidelity=fidelity,
        n_joints=n,
        coordinate_names=names,
        functions=functions,
        # the free-joint spectrum bounds explicit steps (RK4: omega h < 2.785); it is higher than the locked one
        omega_max=float(max(np.max(free, initial=0.0), np.max(locked, initial=0.0))),
        spec=arm,
        info=info,
    )
