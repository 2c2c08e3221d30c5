"""Revolute-prismatic arm: a flexible link sliding in a turning rigid housing (Pan et al. 1990).

The arm of Pan et al.'s Figs 1 and 4.

Geometry
    Joint 1 (revolute, at the origin) turns a rigid housing by ``theta(t)``.  The
    flexible link slides along the housing axis through two frictionless bilateral
    supports at radii ``r_1 < r_2`` (``D = r_2 - r_1``); it is driven axially at one
    end.  Material coordinate ``x`` runs from the inner end E (``x = 0``) to the outer
    tip H (``x = L``).  ``W(t)`` is the overhang of H beyond the outer support, so
    E sits at radius ``r_E = r_2 - L + W`` and the supports at the material points
    ``x_2 = L - W``, ``x_1 = L - D - W`` -- the geometry of
    :mod:`flexctrl.dynamics.fem.sliding_beam`, which this model reduces to for
    ``theta = const`` (a test).  ``0 <= W <= L - D`` keeps both supports on the link.

Pan's Fig 4 joint (``[housing] joint = "clamped"``, ``models/rp_arm_clamped.toml``)
    The link is clamped at its inner end E in the carriage (Eqs 22-23: ``w(0) = w'(0) = 0``, as
    constraint rows with multipliers like the paper) and held transversely by one bearing at the
    housing mouth D' (radius ``support_outer``, material point ``L - W``, Eq 24).  Statically it
    is a beam clamped at E and propped at D' with the overhang ``c = W`` beyond it: under a tip
    force ``P`` the tip deflects ``P c^3 / (3 EI)`` (a cantilever of the current free length) plus
    ``w'(D') c = P c^2 a / (4 EI)`` from the clamped-propped span ``a = L - W`` (test).  Driven at
    E.

Prescribed motion (partial coupling, Eq 42)
    ``theta(t)`` and ``W(t)`` follow the smooth rest-to-rest profile of Eq 57:
    ``W = C1 - C2/T (t - T/(2 pi) sin(2 pi t/T))`` and
    ``theta = theta0 + dtheta (t/T - sin(2 pi t/T)/(2 pi))``, held after ``T``.
    The floating frame translates and rotates with that rigid motion; the unknowns
    are the nodal ``(w, dw/dx)`` of ``N`` equal Hermite elements over the link.

Equations (from T and V of Eqs 5-18 for this frame)
    With ``a_perp(x) = theta'' (r_E + x) + 2 theta' r_E'`` the transverse rigid-body
    acceleration and ``a_ax(x) = r_E'' - theta'^2 (r_E + x)`` the axial one::

        M qdd + (K + K_g(t) - theta'^2 M) q + A(t)^T lam = -int rho N^T a_perp + g_perp int rho N
                                                           (+ payload terms at H)
        A(t) q = 0   (w = 0 at both supports, Eqs 24-25)

    ``-theta'^2 M`` is the centrifugal softening of transverse motion in a rotating
    frame.  Axial shortening (Eqs 16-18, switchable): ``K_g = int F N'^T N'`` with the
    axial force of the rigid motion (tension positive), ``a~ = a_ax - g_ax``:
    driven at E, ``F(x) = -int_x^L rho a~ - m_t a~(L)``; driven at H,
    ``F(x) = int_0^x rho a~``.  ``F`` is quadratic in ``x``; ``K_g`` is assembled
    exactly from three constant matrices with time-varying weights.  Gravity ``g``
    acts in the plane of motion (``g_perp``, ``g_ax`` its components in the frame).

Solution
    :func:`flexctrl.dynamics.fem.newmark_dae.simulate` (Newmark + Baumgarte, Eqs 44-56); the
    problem is linear (``DAEProblem.linear``).

Description and model file
    :class:`~flexctrl.spec.fem_models.RPArmSpec` (``models/rp_arm.toml``, read by
    :func:`~flexctrl.spec.fem_models.load_rp_arm`).

Full coupling (Eq 43: prescribed torque and force, ``theta`` and ``W`` unknowns) is
:mod:`flexctrl.dynamics.fem.rp_arm_full`; the pieces both share are in
:mod:`flexctrl.dynamics.fem.moving_frame`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexctrl.dynamics.fem.moving_frame import (
    ENDS,
    FrameLink,
    NumOrSym,
    RPMotion,
    check_elements,
    is_symbolic,
    prismatic_rows,
)
from flexctrl.dynamics.fem.newmark_dae import DAEProblem, simulate
from flexctrl.errors import SpecError
from flexctrl.spec.fem_models import RPArmSpec

Array = NDArray[np.float64]
INITIAL = ("rest", "static_load")


class RPArmModel:
    """FE model of the sliding link in the turning housing; :meth:`problem` gives its DAE."""

    def __init__(
        self,
        spec: RPArmSpec,
        motion: RPMotion,
        n_elements: int = 8,
        *,
        axial_shortening: bool = True,
        driven_end: Literal["E", "H"] = "E",
    ):
        if driven_end not in ENDS:
            raise SpecError(
                f"value {driven_end!r} is not allowed; allowed: 'E', 'H'", key="driven_end"
            )
        check_elements(n_elements)
        if spec.joint == "clamped" and driven_end != "E":
            raise SpecError(
                f"value {driven_end!r} is not allowed with joint = 'clamped'; allowed: 'E' (the "
                "link is clamped in the carriage that drives it)",
                key="driven_end",
            )
        self.spec, self.motion, self.n = spec, motion, int(n_elements)
        self.axial_shortening, self.driven_end = bool(axial_shortening), driven_end
        s, L = spec, spec.length
        lo, hi = sorted((float(motion.W(0.0)), float(motion.W(motion.T))))
        if not (lo >= 0.0 and hi <= L - s.D):
            raise SpecError(
                f"the overhang W runs over [{lo:g}, {hi:g}] m; allowed: within [0, L - D] = "
                f"[0, {L - s.D:g}] m so that both supports stay on the link",
                key="C1",
            )
        self.link = link = FrameLink(self.n, L, s.mass_per_length, s.EI, s.payload_mass)
        self.le, self.ndof, self.M, self.K = link.le, link.ndof, link.M, link.K
        self.S0, self.S1, self.tip = link.S0, link.S1, link.tip
        self.G_c, self.G_1, self.G_2 = link.G_c, link.G_1, link.G_2
        self.rows = prismatic_rows(s.joint, L, s.D)
        self._cache_t: float | None = None

    # -- rigid motion -------------------------------------------------------------------
    def rigid(self, t: NumOrSym) -> dict[str, NumOrSym]:
        """``r_E`` and its rates (m, m/s, m/s^2), ``theta`` and its rates, gravity in the frame.

        CasADi expressions for a symbolic ``t``.
        """
        m, s = self.motion, self.spec
        val: Callable[[Any], Any]
        cos: Callable[[Any], Any]
        sin: Callable[[Any], Any]
        if is_symbolic(t):
            import casadi as ca  # lazily: the numpy models never need CasADi

            val, cos, sin = (lambda v: v), ca.cos, ca.sin
        else:
            val, cos, sin = float, math.cos, math.sin
        th = val(m.theta(t))
        c, sn = cos(th), sin(th)
        gx, gy = s.gravity
        return {
            "rE": s.support_outer - s.length + val(m.W(t)),
            "rEd": val(m.Wd(t)),
            "rEdd": val(m.Wdd(t)),
            "th": th,
            "thd": val(m.thetad(t)),
            "thdd": val(m.thetadd(t)),
            "g_ax": gx * c + gy * sn,
            "g_perp": -gx * sn + gy * c,
        }

    def axial_force(self, t: float, x: ArrayLike) -> Array:
        """Axial force of the rigid motion (N, tension positive) at material points ``x`` (m)."""
        c0, c1, c2 = self._force_coefficients(t)
        x = np.asarray(x, dtype=float)
        return c0 + c1 * x + c2 * x * x

    def _force_coefficients(self, t: float) -> tuple[float, float, float]:
        return self.link.force_coefficients(self.rigid(t), self.driven_end)

    def support_positions(self, t: float) -> tuple[Array, Array, Array]:
        """Material positions of the constraint points (m) and their first/second time derivatives
        (the two supports; with ``joint = "clamped"`` E twice, for ``w`` and ``w'``, then the
        mouth)."""
        m = self.motion
        v = np.asarray(self.rows.rates)
        return self.rows.points(float(m.W(t))), v * float(m.Wd(t)), v * float(m.Wdd(t))

    def _rows(self, t: float):
        if self._cache_t != t:
            _, xsd, xsdd = self.support_positions(t)
            R = self.rows.at(float(self.motion.W(t)), self.n, self.spec.length)
            Kt, f = self.link.terms(self.rigid(t), self.driven_end, self.axial_shortening)
            self._cache = (R[0], R[1], R[2], xsd, xsdd, Kt, f)
            self._cache_t = t
        return self._cache

    def static(self, tip_force: float, t: float = 0.0) -> tuple[Array, Array]:
        """Static deflection under a transverse force ``tip_force`` (N) at H with the constraints of
        time ``t`` and no frame loads: ``K q + Phi_q^T lam = f``, ``Phi_q q = 0``; returns
        ``(q, lam)``."""
        f = np.zeros(self.ndof)
        f[self.tip] = tip_force
        return self._constrained_static(f, t)

    def _constrained_static(self, f: Array, t: float) -> tuple[Array, Array]:
        A = self._rows(t)[0]
        n, m = self.ndof, A.shape[0]
        S = np.zeros((n + m, n + m))
        S[:n, :n], S[:n, n:], S[n:, :n] = self.K, A.T, A
        sol = np.linalg.solve(S, np.concatenate([f, np.zeros(m)]))
        return sol[:n], sol[n:]

    def stiffness(self, t: float) -> Array:
        """``K + K_g(t) - theta'^2 M`` (without ``K_g`` when axial shortening is off)."""
        return self._rows(t)[5]

    def load(self, t: float) -> Array:
        """Generalised force of the rigid-motion inertia, gravity and payload, N and N m."""
        return self._rows(t)[6]

    def problem(self) -> DAEProblem:
        """The constrained equations of motion as a linear :class:`DAEProblem`."""
        zeros = np.zeros((self.ndof, self.ndof))

        def h_q(q: Array, qd: Array, t: float) -> Array:
            _, R1, R2, xsd, xsdd, _, _ = self._rows(t)
            return -((xsd**2)[:, None] * R2 + xsdd[:, None] * R1)

        def h_qd(q: Array, qd: Array, t: float) -> Array:
            _, R1, _, xsd, _, _, _ = self._rows(t)
            return -2.0 * xsd[:, None] * R1

        return DAEProblem(
            n_q=self.ndof,
            n_c=self.rows.count,
            mass=lambda q, t: self.M,
            force=lambda q, qd, t: self.load(t) - self.stiffness(t) @ q,
            phi=lambda q, t: self._rows(t)[0] @ q,
            phi_q=lambda q, t: self._rows(t)[0],
            phi_t=lambda q, t: self._rows(t)[3] * (self._rows(t)[1] @ q),
            h=lambda q, qd, t: h_q(q, qd, t) @ q + h_qd(q, qd, t) @ qd,
            force_q=lambda q, qd, t: -self.stiffness(t),
            force_qd=lambda q, qd, t: zeros,
            h_q=h_q,
            h_qd=h_qd,
            linear=True,
        )

    def initial_shape(
        self,
        kind: Literal["rest", "static_load"] = "rest",
        tip_deflection: float = 0.01,
        tracked_end: Literal["E", "H"] = "H",
    ) -> Array:
        """Initial nodal values: zero (``"rest"``), or a static deflection.

        The deflection under a uniform load with the t = 0 supports, scaled so that
        ``tracked_end`` deflects ``tip_deflection`` (m).
        """
        if kind == "rest":
            return np.zeros(self.ndof)
        if kind != "static_load":
            raise SpecError(
                f"value {kind!r} is not allowed; allowed: {', '.join(map(repr, INITIAL))}",
                key="initial",
            )
        q = self._constrained_static(self.S0 / self.spec.mass_per_length, 0.0)[0]
        dof = 0 if tracked_end == "E" else self.tip
        return q * (tip_deflection / q[dof])

    def vibration_energy(self, q: Array, qd: Array) -> float:
        """``1/2 qd^T M qd + 1/2 q^T K q`` (J): kinetic energy in the frame plus strain energy."""
        return 0.5 * float(qd @ self.M @ qd) + 0.5 * float(q @ self.K @ q)


@dataclass(frozen=True)
class RPArmResult:
    """Response of :func:`simulate_rp_arm`.

    ``t`` (s), ``W`` (m), ``theta`` (rad), ``tip_y``: transverse displacement of the
    tracked end in the link frame (m), ``tip_world``: position of H (m, shape (T, 2),
    axial shortening not included), ``q`` nodal dofs, ``qd`` rates, ``lam`` support
    forces (N), ``phi_violation`` (m), ``phidot_violation`` (m/s), ``wall_time`` (s),
    ``model`` the :class:`RPArmModel`.
    """

    model: RPArmModel
    dt: float
    t: Array
    W: Array
    theta: Array
    tip_y: Array
    tip_world: Array
    q: Array
    qd: Array
    lam: Array
    phi_violation: Array
    phidot_violation: Array
    wall_time: float


def simulate_rp_arm(
    spec: RPArmSpec,
    motion: RPMotion,
    n_elements: int = 8,
    dt: float = 1e-3,
    duration: float | None = None,
    *,
    gamma: float = 5.0,
    beta: float = 5.0,
    alpha: float = 0.25,
    delta: float = 0.5,
    axial_shortening: bool = True,
    driven_end: Literal["E", "H"] = "E",
    tracked_end: Literal["E", "H"] = "H",
    initial: Literal["rest", "static_load"] = "rest",
    tip_deflection: float = 0.01,
    max_violation: float = 1e-3,
) -> RPArmResult:
    """Simulate the prescribed-motion R-P arm with Newmark + Baumgarte (see module docstring).

    Parameters
    ----------
    n_elements
        Equal Hermite elements over the link.
    dt, duration
        Step and simulated time, s (``duration`` defaults to ``max(T, 1 s)``).
    gamma, beta, alpha, delta
        Baumgarte (1/s) and Newmark parameters.
    axial_shortening, driven_end
        Geometric stiffness of the rigid-motion axial force, and where the axial drive acts.
    tracked_end
        End whose transverse displacement is reported as ``tip_y``.
    initial, tip_deflection
        Start at rest undeformed, or from the scaled static deflection (as Buffinton & Kane).
    max_violation
        Bound (m) on the position-level constraint violation.
    """
    if tracked_end not in ENDS:
        raise SpecError(
            f"value {tracked_end!r} is not allowed; allowed: 'E', 'H'", key="tracked_end"
        )
    model = RPArmModel(
        spec, motion, n_elements, axial_shortening=axial_shortening, driven_end=driven_end
    )
    t_end = max(motion.T, 1.0) if duration is None else float(duration)
    q0 = model.initial_shape(initial, tip_deflection, tracked_end)
    res = simulate(
        model.problem(),
        q0,
        np.zeros_like(q0),
        t_end,
        dt,
        gamma=gamma,
        beta=beta,
        alpha=alpha,
        delta=delta,
        max_violation=max_violation,
    )
    dof = 0 if tracked_end == "E" else model.tip
    theta = motion.theta(res.t)
    radius = spec.support_outer + motion.W(res.t)  # r_E + L
    w_tip = res.q[:, model.tip]
    c, s = np.cos(theta), np.sin(theta)
    tip_world = np.stack([c * radius - s * w_tip, s * radius + c * w_tip], axis=1)
    return RPArmResult(
        model=model,
        dt=res.dt,
        t=res.t,
        W=motion.W(res.t),
        theta=theta,
        tip_y=res.q[:, dof],
        tip_world=tip_world,
        q=res.q,
        qd=res.qd,
        lam=res.lam,
        phi_violation=res.phi_violation,
        phidot_violation=res.phidot_violation,
        wall_time=res.wall_time,
    )
