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

Kinematic options (``docs/explanation/assumed-modes.md`` sections 10, 13, 14)
    ``axial_shortening``: a bent link's points move towards its root by
    ``1/2 int_0^x w'^2`` (second-order foreshortening).  ``tip_rotation``: the next link's
    frame turns by Eq 7's linearised rotation or exactly by the tip slope; the exact one is
    the default with axial shortening, the kinematics being consistent only then.
    ``static_correction``: each link but the last gets the static shape under a tip moment
    after its modes (:mod:`flexctrl.modal.static_correction`).  ``axial_stretch``: one
    elongation ``e_i`` (m) per link with modes, appended to ``q`` (``e1..en``), a uniform
    strain ``e_i / L_i`` with strain energy ``1/2 (EA_i / L_i) e_i^2`` and the finite
    elements' damping ``(2 zeta_i / omega_1i) EA_i / L_i``.  The last two need frozen modes.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import casadi as ca
import numpy as np

from flexctrl.dynamics.amm_equations import lagrange_equations, model_functions
from flexctrl.dynamics.amm_kinematics import (
    TIP_ROTATIONS,
    LinkModal,
    arm_expressions,
    coordinate_names,
    flexible_offsets,
    stretched_links,
)
from flexctrl.dynamics.amm_modal import frozen_modal, scheduled_modal
from flexctrl.dynamics.coupled_damping import coupled_modal_damping
from flexctrl.dynamics.model import Model
from flexctrl.dynamics.natural_frequencies import locked_spectrum, natural_frequencies
from flexctrl.errors import SpecError
from flexctrl.spec.arm import ArmSpec
from flexctrl.spec.damping import DAMPING_FORMS
from flexctrl.spec.fidelity import Fidelity
from flexctrl.spec.joint_support import require_revolute

MODES = ("frozen", "scheduled")
DAMPING = DAMPING_FORMS
SOLVERS = ("ldl", "qr")
CORIOLIS = ("bodies", "lagrange")

#: The assumed-modes default of ``axial_shortening`` when neither the call, the scene nor the
# : model file sets it: off.  The effect is correct physics (docs/explanation/assumed-modes.md
# section 12), but the
#: shipped controllers, tunings and studies are tuned on the model without it, and the
#: compiled step costs more with it.  Turn it on per model file or scene
#: (``axial_shortening = true``).
AMM_AXIAL_SHORTENING = False

#: The default of ``axial_stretch``: off (``docs/explanation/assumed-modes.md`` section 14).
AMM_AXIAL_STRETCH = False

#: The default of ``static_correction``: off (``docs/explanation/assumed-modes.md`` section 13).
AMM_STATIC_CORRECTION = False


def _check_choice(value: str, allowed: tuple[str, ...], key: str) -> str:
    if value not in allowed:
        raise SpecError(
            f"value {value!r} is not allowed; allowed: {', '.join(repr(a) for a in allowed)}",
            key=key,
        )
    return value


@dataclass(frozen=True)
class _Options:
    """The build options of :func:`build_amm`, defaults resolved and validated."""

    modes: str
    damping: str
    solver: str
    coriolis: str
    shortening: bool
    rotation: str
    stretch: bool
    n_modes: list[int]
    q_ref: np.ndarray
    fidelity: Fidelity
    corrected: list[bool]


def _options(
    arm: ArmSpec,
    n_modes: int | Sequence[int],
    *,
    modes: str,
    reference_q: Sequence[float] | np.ndarray | None,
    damping: str | None,
    solver: str,
    fidelity: Fidelity | None,
    coriolis: str,
    axial_shortening: bool | None,
    tip_rotation: str | None,
    static_correction: bool | None,
    axial_stretch: bool | None,
) -> _Options:
    """The options of :func:`build_amm` with the arm's and the module's defaults, validated."""
    _check_choice(modes, MODES, "modes")
    damping = arm.damping_form if damping is None else damping
    _check_choice(damping, DAMPING, "damping")
    if damping == "modal" and (modes == "scheduled" or arm.damping_zeta is None):
        why = "scheduled modes" if modes == "scheduled" else "the arm has no damping_zeta"
        raise SpecError(
            f"damping 'modal' is not allowed here ({why}); allowed: frozen modes and the model "
            "file's damping_form = 'modal' with damping_zeta, or another damping form",
            key="damping",
        )
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
    if isinstance(n_modes, Sequence | np.ndarray):
        counts = [int(k) for k in n_modes]
    else:
        counts = [int(n_modes)] * n
    if len(counts) != n or any(not 0 <= k <= 6 for k in counts):
        raise SpecError(
            f"n_modes {counts!r} is not allowed; allowed: one count 0..6 or one per link "
            f"({n} links)",
            key="n_modes",
        )
    if fidelity is None:
        fidelity = Fidelity("amm", counts[0]) if len(set(counts)) == 1 else Fidelity("amm")
    correction = AMM_STATIC_CORRECTION if static_correction is None else bool(static_correction)
    corrected = [correction and i < n - 1 and nf > 0 for i, nf in enumerate(counts)]
    if any(corrected) and modes == "scheduled":
        raise SpecError(
            "value True is not allowed with modes='scheduled'; allowed: static_correction "
            "with frozen modes",
            key="static_correction",
        )
    if axial_stretch is None:
        axial_stretch = AMM_AXIAL_STRETCH if arm.axial_stretch is None else arm.axial_stretch
    stretch = bool(axial_stretch)
    if stretch and modes == "scheduled":
        raise SpecError(
            "value True is not allowed with modes='scheduled'; allowed: axial_stretch with "
            "frozen modes",
            key="axial_stretch",
        )
    return _Options(
        modes=modes,
        damping=damping,
        solver=solver,
        coriolis=coriolis,
        shortening=shortening,
        rotation=rotation,
        stretch=stretch,
        n_modes=counts,
        q_ref=arm.configuration_or_default(reference_q),
        fidelity=fidelity,
        corrected=corrected,
    )


def build_amm(
    arm: ArmSpec,
    n_modes: int | Sequence[int],
    *,
    modes: Literal["frozen", "scheduled"] = "frozen",
    reference_q: Sequence[float] | np.ndarray | None = None,
    damping: Literal["ratio", "paper", "stiffness", "modal"] | None = None,
    solver: Literal["ldl", "qr"] = "ldl",
    fidelity: Fidelity | None = None,
    lookups: Sequence[ca.Function | None] | None = None,
    coriolis: Literal["bodies", "lagrange"] = "bodies",
    axial_shortening: bool | None = None,
    tip_rotation: Literal["linearized", "exact"] | None = None,
    static_correction: bool | None = None,
    axial_stretch: bool | None = None,
) -> Model:
    """Build the assumed-modes model of ``arm`` (see the module docstring).

    Parameters
    ----------
    arm
        The arm (payload included).
    n_modes
        Modes per link (one number for every link, or one per link), 0..6.
    modes
        ``"frozen"`` (modes at ``reference_q``) or ``"scheduled"`` (looked up from ``q``).
    reference_q
        Joint angles (rad) of the frozen modes and of ``omega_max``; default the arm's.
    damping
        ``"ratio"``, ``"paper"`` or ``"stiffness"`` (module docstring); None: the arm's.
    solver
        Solve of ``M qdd = rhs``: ``"ldl"`` (explicit LDL^T) or ``"qr"`` (``casadi.solve``).
    fidelity
        Recorded in the model (default ``amm:N`` when all links have N modes).
    lookups
        For ``"scheduled"``: one table Function per link (None without modes), as
        :attr:`flexctrl.modal.lookup.ModalLookup.function`; default: built.
    coriolis
        ``"bodies"`` (``sum J^T G Jdot qd``, smaller code) or ``"lagrange"`` (generic,
        always for scheduled modes); both exact.
    axial_shortening
        Second-order kinematics; default the arm's, else :data:`AMM_AXIAL_SHORTENING`.
    tip_rotation
        ``"linearized"`` (Eq 7) or ``"exact"``; default exact with axial shortening.
    static_correction
        A tip-moment shape per link but the last; default :data:`AMM_STATIC_CORRECTION`.
    axial_stretch
        An elongation per link; default the arm's, else :data:`AMM_AXIAL_STRETCH`.

    Returns
    -------
    Model
        Functions ``M, c, g, K, D, f, energies, tip, hubs, deflection``
        (see :mod:`flexctrl.dynamics.model`).
    """
    start = time.perf_counter()
    require_revolute(
        arm,
        "the assumed-modes and rigid arm",
        "prismatic joints: model files of kind rp_arm or telescoping, as models/rp_arm.toml",
    )
    opts = _options(
        arm,
        n_modes,
        modes=modes,
        reference_q=reference_q,
        damping=damping,
        solver=solver,
        fidelity=fidelity,
        coriolis=coriolis,
        axial_shortening=axial_shortening,
        tip_rotation=tip_rotation,
        static_correction=static_correction,
        axial_stretch=axial_stretch,
    )
    return _build(arm, opts, lookups, start)


def _build(
    arm: ArmSpec, opts: _Options, lookups: Sequence[ca.Function | None] | None, start: float
) -> Model:
    """The model of ``arm`` with the options ``opts`` (``start``: when the build began)."""
    frozen, link_freqs = frozen_modal(arm, opts.q_ref, opts.n_modes, opts.corrected)
    counts = [md.n_modes for md in frozen]  # with the correction shapes
    n = arm.n_links
    stretched = stretched_links(counts) if opts.stretch else []
    names = coordinate_names(n, counts) + tuple(f"e{i + 1}" for i in stretched)
    N = len(names)
    q, qd, u = ca.SX.sym("q", N), ca.SX.sym("qd", N), ca.SX.sym("u", n)
    scheduled = opts.modes == "scheduled" and N > n
    if scheduled:
        modal, expansion = scheduled_modal(arm, q, counts, lookups)
        ex = arm_expressions(
            arm,
            modal,
            q,
            shape_rates=True,
            axial_shortening=opts.shortening,
            tip_rotation=opts.rotation,
        )
    else:
        modal, expansion = frozen, None
        ex = arm_expressions(
            arm,
            modal,
            q,
            qd if opts.coriolis == "bodies" else None,
            axial_shortening=opts.shortening,
            tip_rotation=opts.rotation,
            axial_stretch=opts.stretch,
        )
    K, D, E_el = _stiffness_and_damping(arm, modal, opts, stretched, names, q, ex.elastic_energy)
    expr = lagrange_equations(ex, K, D, E_el, (q, qd, u), opts.solver, scheduled)
    functions = model_functions(expr, K, D, (q, qd, u), scheduled, expansion)
    if opts.damping == "modal" and arm.damping_zeta is not None:
        # the coupled modes at the reference pose need M, so the equations are formed twice
        q0 = np.concatenate([opts.q_ref, np.zeros(N - n)])
        D = D + ca.SX(
            coupled_modal_damping(
                np.array(functions["M"](q0)), np.array(functions["K"]()["K"]), arm.damping_zeta
            )
        )
        expr = lagrange_equations(ex, K, D, E_el, (q, qd, u), opts.solver, scheduled)
        functions = model_functions(expr, K, D, (q, qd, u), scheduled, expansion)
    locked, free = _spectra(functions, opts.q_ref, n, scheduled)
    info = {
        "family": "amm",
        "modes": "scheduled" if scheduled else "frozen",
        "modes_requested": opts.modes,
        "n_modes": list(counts),
        "flexible_offsets": flexible_offsets(n, counts),
        "reference_q": opts.q_ref.tolist(),
        "link_frequencies_rad_s": link_freqs,
        "locked_frequencies_rad_s": locked.tolist(),
        "free_frequencies_rad_s": free.tolist(),
        **_derivation_facts(opts, scheduled),
        "build_time_s": time.perf_counter() - start,
    }
    return Model(
        name=_model_name(arm, counts, info, opts),
        fidelity=opts.fidelity,
        n_joints=n,
        coordinate_names=names,
        functions=functions,
        # the free-joint spectrum bounds explicit steps (RK4: omega h < 2.785); it is higher
        # than the locked one
        omega_max=float(max(np.max(free, initial=0.0), np.max(locked, initial=0.0))),
        spec=arm,
        info=info,
    )


def _stiffness_and_damping(
    arm: ArmSpec,
    modal: Sequence[LinkModal],
    opts: _Options,
    stretched: Sequence[int],
    names: Sequence[str],
    q: ca.SX,
    elastic_energy: ca.SX,
) -> tuple[ca.SX, ca.SX, ca.SX]:
    """``(K, D, E_el)``: modal stiffness and damping (Eqs 65-68), then the elongations'."""
    n = arm.n_links
    stiffness: list[Any] = [ca.SX(0)] * n
    damp: list[Any] = [ca.SX(arm.joints[i].friction) for i in range(n)]
    for link, md in zip(arm.links, modal):
        for j in range(md.n_modes):
            omega = md.omega[j]
            stiffness.append(link.mass * omega**2)
            if opts.damping == "modal":  # fitted on the coupled modes afterwards (_build)
                damp.append(ca.SX(0))
            elif opts.damping == "stiffness":  # the finite elements' (2 zeta / omega_1) K, modal
                damp.append(2.0 * link.damping_ratio(0) / float(md.omega[0]) * link.mass * omega**2)
            else:
                scale = link.mass if opts.damping == "ratio" else 1.0
                damp.append(2.0 * link.damping_ratio(j) * omega * scale)
    E_el = elastic_energy
    for i in stretched:  # elongations e_i: strain energy 1/2 (EA / L) e^2
        link, md = arm.links[i], modal[i]
        k_axial = link.axial_stiffness() / link.length
        stiffness.append(ca.SX(k_axial))
        E_el = E_el + 0.5 * k_axial * q[names.index(f"e{i + 1}")] ** 2
        # damped as the finite elements' links: (2 zeta / omega_1) k, omega_1 the link's first
        # clamped-mass mode
        ratio = 0.0 if opts.damping == "modal" else link.damping_ratio(0)
        damp.append(ca.SX(2.0 * ratio / float(md.omega[0]) * k_axial))
    return ca.diag(ca.vertcat(*stiffness)), ca.diag(ca.vertcat(*damp)), E_el


def _spectra(
    functions: dict[str, ca.Function], q_ref: np.ndarray, n: int, scheduled: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Locked-joint and free-joint natural frequencies (rad/s) at ``q_ref``, ``q_f = 0``."""
    N = functions["M"].size1_in(0)
    if N == n:
        return np.zeros(0), np.zeros(0)
    q0 = np.concatenate([q_ref, np.zeros(N - n)])
    M0 = np.array(functions["M"](q0))
    K0 = np.array(functions["K"](q0) if scheduled else functions["K"]()["K"])
    locked = locked_spectrum(M0, K0, n)
    # free joints (no gravity): the elastic coordinates see the Schur complement of M
    flex = np.arange(n, N)
    schur = M0[np.ix_(flex, flex)] - M0[n:, :n] @ np.linalg.solve(M0[:n, :n], M0[:n, n:])
    free = natural_frequencies(K0[np.ix_(flex, flex)], 0.5 * (schur + schur.T))
    return locked, free


def _derivation_facts(opts: _Options, scheduled: bool) -> dict[str, Any]:
    """The ``info`` entries that record how the equations were derived."""
    return {
        "damping": opts.damping,
        "solver": opts.solver,
        "coriolis": "lagrange" if scheduled else opts.coriolis,
        "axial_shortening": opts.shortening,
        "axial_stretch": opts.stretch,
        "static_correction": [bool(c) for c in opts.corrected],
        "elastic_rotation": "linearised E_i = [[1, -w'], [w', 1]] (Eq 7)"
        if opts.rotation == "linearized"
        else "exact rotation by the tip slope w'_ie",
        "g_convention": "dU_g/dq + dU_el/dq - K(q) q" if scheduled else "dU_g/dq",
        "input_matrix": "tau acts on q1..qn",
    }


def _model_name(arm: ArmSpec, counts: Sequence[int], info: dict[str, Any], opts: _Options) -> str:
    """``"<arm> amm 2/2/2 frozen"`` and the options that differ from the default kinematics."""
    default_rotation = "exact" if opts.shortening else "linearized"
    return "".join(
        [
            f"{arm.name} amm {'/'.join(map(str, counts))} {info['modes']}",
            "" if opts.shortening else " no-shortening",
            " static-correction" if any(opts.corrected) else "",
            " axial-stretch" if opts.stretch else "",
            "" if opts.rotation == default_rotation else f" {opts.rotation}-rotation",
        ]
    )
