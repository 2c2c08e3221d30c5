"""Revolute-prismatic arm, full coupling (Pan et al. 1990, Eq 43): ``theta``, ``W`` are unknowns.

The arm, its geometry and the prescribed-motion model (partial coupling, Eq 42) are described in
:mod:`flexctrl.dynamics.fem.rp_arm`; the description is
:class:`~flexctrl.spec.fem_models.RPArmSpec`.

Equations (:class:`RPArmFullModel`, :func:`simulate_rp_arm_full`)
    Coordinates ``z = (q, theta, W)``; inputs the joint torque ``tau`` and the axial force ``F``
    on a carriage (mass ``m_c``) that rides the housing axially and is attached to E axially
    only.  A material point sits at ``(r_E + x - s(x), w(x))`` in the turning frame with the
    shortening ``s(x) = 1/2 int_0^x w'^2`` measured from the driven end E, so its velocity is
    ``(W' - s_t - theta' w, w_t + theta' (r_E + x - s))``.  ``T`` keeps every term up to second
    order in ``(q, qd)``::

        T = 1/2 rho L W'^2 - W' qd.Gs q - W' theta' S0.q + 1/2 theta'^2 q.M q + 1/2 qd.M qd
            + theta' qd.(r_E S0 + S1) + 1/2 theta'^2 rho (L r_E^2 + L^2 r_E + L^3/3)
            - 1/2 theta'^2 q.(r_E Gs + Gx) q + payload (same expansion at x = L)
            + 1/2 J_h theta'^2 + 1/2 m_c (W'^2 + r_E^2 theta'^2)
        V = 1/2 q.K q - g_ax (rho (L r_E + L^2/2) - 1/2 q.Gs q + m_t (r_E + L - s(L)) + m_c r_E)
            - g_perp (S0.q + m_t w(L))

    with ``Gs = rho int (L - x) N'^T N'`` (``int rho s = 1/2 q.Gs q``) and ``Gx = rho int (L^2 -
    x^2)/2 N'^T N'``.  ``M(z)``, the velocity terms and gravity follow by CasADi differentiation
    of ``L = T - V``; ``Q = (0, tau, F)``.  With ``theta(t)``, ``W(t)`` prescribed the ``q`` rows
    are exactly the partial-coupling equations of :mod:`~flexctrl.dynamics.fem.rp_arm`, Pan's
    ``K_g`` included (the ``- W' qd.Gs q`` and ``- theta'^2 ... Gs`` terms produce it), which a test
    checks; unlike Pan's ``K_g`` with the nominal axial force, the shortening here stays a
    conservative part of ``T``, so ``M`` is symmetric and the free arm conserves ``T + V``.  The
    supports ``w(L - W - d_k) = 0`` now depend on the unknown ``W``: ``Phi_z = (R0, 0, -R1 q)``,
    ``h = 2 W' R1 qd - W'^2 R2 q``.  With Pan's Fig 4 joint (``spec.joint = "clamped"``) the rows
    are ``w(0) = w'(0) = 0`` (fixed on the link, Eqs 22-23) and the mouth bearing ``w(L - W) = 0``
    (Eq 24).

The Lagrangian pieces, the constraint algebra and the runner are shared with the telescoping pair
(:mod:`flexctrl.dynamics.fem.full_coupling`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexctrl.dynamics.fem.full_coupling import (
    FullCouplingResult,
    RPForces,
    SlidingFullModel,
    link_energies,
    payload_energies,
)
from flexctrl.dynamics.fem.moving_frame import (
    ENDS,
    FrameLink,
    RPMotion,
    check_elements,
    prismatic_rows,
)
from flexctrl.dynamics.fem.newmark_dae import DAEResult
from flexctrl.errors import SimulationError, SpecError
from flexctrl.spec.fem_models import RPArmSpec

Array = NDArray[np.float64]
__all__ = ["RPArmFullModel", "RPArmFullResult", "RPForces", "simulate_rp_arm_full"]


class RPArmFullModel(SlidingFullModel):
    """The R-P arm with the nominal joint coordinates among the unknowns (full coupling, Eq 43).

    Coordinates ``z = (q, theta, W)``: the ``2 (N + 1)`` nodal ``(w, w')`` of the sliding link, the
    housing angle (rad) and the overhang ``W`` (m) beyond the outer support (or the mouth).
    ``M(z)``, the velocity terms and the generalised forces come from the Lagrangian by CasADi
    automatic differentiation (module docstring); the constraint rows and their derivatives are
    formed in numpy, because a row follows its support from element to element as ``W`` changes.

    ``drive``: an :class:`RPForces` (torque and force prescribed) or an :class:`RPMotion`; the
    latter adds the constraints ``theta - theta(t) = 0`` and ``W - W(t) = 0`` whose multipliers are
    minus the joint torque and axial force the motion needs.
    """

    def __init__(
        self,
        spec: RPArmSpec,
        drive: RPForces | RPMotion,
        n_elements: int = 8,
        *,
        axial_shortening: bool = True,
    ):
        import casadi as ca  # lazily: the numpy models never need CasADi

        check_elements(n_elements)
        if not isinstance(drive, (RPForces, RPMotion)):
            raise SpecError(
                f"value {drive!r} is not allowed; allowed: an RPForces or an RPMotion", key="drive"
            )
        self.spec, self.drive, self.n = spec, drive, int(n_elements)
        self.axial_shortening = bool(axial_shortening)
        s, L = spec, spec.length
        motion_driven = isinstance(drive, RPMotion)
        W0 = float(drive.W(0.0)) if isinstance(drive, RPMotion) else float(drive.W0)
        if not 0.0 <= W0 <= L - s.D:
            raise SpecError(
                f"value W(0) = {W0!r} m is not allowed; allowed: within [0, L - D] = "
                f"[0, {L - s.D:g}] m",
                key="W0" if not motion_driven else "C1",
            )
        link = FrameLink(self.n, L, s.mass_per_length, s.EI)
        self.link, self.le, self.ne, self.tip = link, link.le, link.ndof, link.tip
        self.rows = prismatic_rows(s.joint, L, s.D)
        z, zd = ca.SX.sym("z", self.ne + 2), ca.SX.sym("zd", self.ne + 2)
        q, th, W = z[: self.ne], z[self.ne], z[self.ne + 1]
        qd, thd, Wd = zd[: self.ne], zd[self.ne], zd[self.ne + 1]
        rE = s.support_outer - L + W
        gx, gy = s.gravity
        g_ax, g_perp = gx * ca.cos(th) + gy * ca.sin(th), -gx * ca.sin(th) + gy * ca.cos(th)
        args = (q, qd, rE, Wd, thd, g_ax, g_perp, self.axial_shortening)
        T_l, V_l = link_energies(link, *args)
        T_p, V_p = payload_energies(link, s.payload_mass, *args)
        T = (
            T_l
            + T_p
            + 0.5 * s.hub_inertia * thd**2
            + 0.5 * s.carriage_mass * (Wd**2 + rE**2 * thd**2)
        )
        V = V_l + V_p - g_ax * s.carriage_mass * rE
        self._build(z, zd, T, V)

    def check_W(self, W: float, t: float) -> None:
        """Raise :class:`SimulationError` when the overhang ``W`` (m) leaves the stroke at ``t``."""
        s = self.spec
        if not -1e-12 <= W <= s.length - s.D + 1e-12:
            raise SimulationError(
                f"at t = {t:.6g} s the overhang W = {W:.6g} m left [0, L - D] = "
                f"[0, {s.length - s.D:g}] m: a support slid off the link (full coupling; "
                "reduce the axial force or the duration)"
            )

    def _parts(self, W: float) -> list[tuple[Array, Array]]:
        s = self.spec
        W = min(max(W, 0.0), s.length - s.D)
        return [(self.rows.at(W, self.n, s.length), np.asarray(self.rows.rates))]

    def support_rows(self, W: float, t: float = math.nan) -> Array:
        """``R[d, k]``: rows of the constraints' ``d``-th derivative (``d = 0..3``) at ``W``."""
        return self.contact_parts(W, t)[0][0]


@dataclass(frozen=True)
class RPArmFullResult(FullCouplingResult):
    """Response of :func:`simulate_rp_arm_full`: the fields of
    :class:`~flexctrl.dynamics.fem.full_coupling.FullCouplingResult` (``lam``: the support, or clamp
    and mouth, forces) and ``tip_world``, the position of H (m, shape (T, 2), axial shortening not
    included)."""

    tip_world: Array


def simulate_rp_arm_full(
    spec: RPArmSpec,
    drive: RPForces | RPMotion,
    n_elements: int = 8,
    dt: float = 1e-3,
    duration: float = 1.0,
    *,
    gamma: float = 5.0,
    beta: float = 5.0,
    alpha: float = 0.25,
    delta: float = 0.5,
    axial_shortening: bool = True,
    tracked_end: Literal["E", "H"] = "H",
    max_violation: float = 1e-3,
    newton_tol: float = 1e-10,
    max_iterations: int = 30,
    initial_q: ArrayLike | None = None,
) -> RPArmFullResult:
    """Simulate the fully coupled R-P arm (Eq 43) with Newmark + Baumgarte (Newton on ``z, lam``).

    Parameters
    ----------
    drive
        :class:`RPForces` (joint torque and axial force prescribed, ``theta`` and ``W`` solved for)
        or :class:`RPMotion` (both prescribed through constraints; reports the torque and force
        needed).
    n_elements, dt, duration
        Hermite elements over the link; step and simulated time, s.
    gamma, beta, alpha, delta
        Baumgarte (1/s) and Newmark parameters.
    axial_shortening
        Keep the ``1/2 int w'^2`` shortening in the kinematics of the link (drive at E).
    tracked_end
        End reported as ``tip_y``.
    max_violation
        Bound (m) on the support-constraint violation.
    newton_tol, max_iterations
        Newton stopping rule of :func:`flexctrl.dynamics.fem.newmark_dae.simulate`.
    initial_q
        Initial nodal values (m, rad), e.g.
        :meth:`flexctrl.dynamics.fem.rp_arm.RPArmModel.initial_shape`; default undeformed.  Must
        satisfy the constraints (checked, 1e-9 m).  If the link slides (``Wd0 != 0``) the nodal
        velocities start as the smallest (mass-weighted) ones that keep the supports at rest on the
        deflected link, ``w_t(x_k) = W' w'(x_k)``, so that ``Phidot = 0``.

    Raises
    ------
    SimulationError
        A support slid off the link (``W`` left ``[0, L - D]``) or a constraint violation diverged.
    SolverError
        Newton failed to converge.
    """
    if tracked_end not in ENDS:
        raise SpecError(
            f"value {tracked_end!r} is not allowed; allowed: 'E', 'H'", key="tracked_end"
        )
    model = RPArmFullModel(spec, drive, n_elements, axial_shortening=axial_shortening)
    res, torque, force, vp, vv = model.run(
        dt,
        duration,
        initial_q,
        gamma=gamma,
        beta=beta,
        alpha=alpha,
        delta=delta,
        max_violation=max_violation,
        newton_tol=newton_tol,
        max_iterations=max_iterations,
    )
    return _result(spec, model, res, (torque, force), (vp, vv), tracked_end)


def _result(
    spec: RPArmSpec,
    model: RPArmFullModel,
    res: DAEResult,
    inputs: tuple[Array, Array],
    violations: tuple[Array, Array],
    tracked_end: str,
) -> RPArmFullResult:
    """The run ``res`` of ``model`` as an :class:`RPArmFullResult` (the tip in the world frame)."""
    torque, force = inputs
    vp, vv = violations
    ne, ith, iW = model.ne, model.ith, model.iW
    theta, W = res.q[:, ith], res.q[:, iW]
    radius = spec.support_outer + W
    w_tip = res.q[:, model.tip]
    c, s = np.cos(theta), np.sin(theta)
    dof = 0 if tracked_end == "E" else model.tip
    return RPArmFullResult(
        model=model,
        dt=res.dt,
        t=res.t,
        theta=theta,
        thetad=res.qd[:, ith],
        W=W,
        Wd=res.qd[:, iW],
        torque=torque,
        force=force,
        q=res.q[:, :ne],
        qd=res.qd[:, :ne],
        lam=res.lam[:, : model.rows.count],
        tip_y=res.q[:, dof],
        tip_world=np.stack([c * radius - s * w_tip, s * radius + c * w_tip], 1),
        phi_violation=vp,
        phidot_violation=vv,
        newton_iterations=res.newton_iterations,
        wall_time=res.wall_time,
    )
