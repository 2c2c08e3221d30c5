"""Beam moving over two bilateral supports (Pan, Scott & Ulsoy 1990, Sec. 5; Buffinton & Kane 1985).

Geometry (decided from the paper's text; its Fig. 6 is not available)
    Uniform beam, ends E and H, material coordinate ``x`` from E (``x = 0``) to H
    (``x = L``).  Two frictionless bilateral supports, ``D`` apart, are fixed in
    space; the beam slides through them.  ``W(t)`` (Eq 57) is the overhang beyond
    the support on the H side, so the supports sit at the material points
    ``x_s2 = L - W`` and ``x_s1 = L - D - W`` and the E-side overhang is
    ``L - D - W``.  Both push cases start with ``W = 0.725`` (long overhang at H,
    0.025 m at E) and end at ``W = 0.025``: the beam moves toward E, H is the
    trailing end and is tracked.  The pull case starts at ``W = 0.025`` (long
    overhang at E) and ends at ``W = 0.725``: the beam moves toward H, E is tracked.
    In both the tracked end is the one whose long overhang is drawn in through the
    supports, and the initial shape is the static deflection under a uniform load
    scaled so that this end deflects 0.01 m.  Mirroring ``x -> L - x`` maps the
    pull case onto the push case exactly (same support paths, same initial shape,
    tracked end onto tracked end), so without axial shortening the two tip
    responses are identical -- the paper's remark, and a test.

Floating frame and equations
    The frame translates with the rigid axial motion (origin at E, ``X_E = const +
    W``), so it carries no rotation and the transverse acceleration of a material
    point is just ``w_tt``.  Unknowns are the nodal ``(w, theta = dw/dx)`` of ``n``
    equal Hermite elements; ``M qdd + (K + K_g(t)) q + A(t)^T lam = 0`` with the
    constraints ``Phi_k = w(x_sk(t)) = A_k(t) q = 0``; each row holds the Hermite
    shape functions of the element currently containing ``x_sk``, so it switches
    element as the support slides.  ``h = -2 xd_s w'(x_s)(qd) - (xd_s^2 w'' +
    xdd_s w')(q)`` per row with ``xd_s = -Wd``, ``xdd_s = -Wdd``.

Axial shortening (Eqs 16-18)
    The driving axial force acts at one end (the *driven* end, H in all three
    cases: a drive behind the supports pushes the beam out toward E and pulls it
    back toward H); the other end is free.  With ``s`` the distance from the driven
    end and ``a_in`` the rigid acceleration component pointing from the driven end
    into the beam, the axial force (tension positive) is
    ``F(s) = -rho a_in (L - s)`` (Eq 18 with no payload).  For the H drive,
    ``a_in = -Wdd`` and ``F(x) = rho Wdd x``.  Push: ``Wdd < 0`` while accelerating,
    the driven end trails, compression (softening); pull: ``Wdd > 0`` while
    accelerating, the driven end leads, tension (stiffening); the roles swap while
    braking.  ``F`` is linear in ``x``, so ``K_g(t) = Wdd(t) G`` with ``G`` assembled
    once from the closed-form linear-force element matrix.  ``axial_shortening =
    False`` drops ``K_g``.

Time history: ``W(t)`` by Eq 57 for ``0 <= t <= T`` and ``W(T)`` afterwards
(``Wd`` and ``Wdd`` vanish at ``t = 0`` and ``t = T``, so the release at rest is
consistent with the constraints).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexctrl.beam.elements import (
    assemble_beam,
    assemble_geometric_stiffness,
    hermite_shape,
    locate,
)
from flexctrl.dynamics.fem.newmark_dae import DAEProblem, simulate

Array = NDArray[np.float64]


@dataclass(frozen=True)
class SlidingBeamCase:
    """One prescribed-motion case; SI units (m, s, kg/m, N m^2).

    ``W(t) = C1 - C2/T (t - T/(2 pi) sin(2 pi t / T))`` is the H-side overhang.
    """

    name: str
    C1: float
    C2: float
    T: float
    tracked_end: Literal["E", "H"]
    driven_end: Literal["E", "H"] = "H"
    L: float = 1.0
    rho: float = 1.0
    EI: float = 1.0
    D: float = 0.25
    tip_deflection: float = 0.01

    def W(self, t: ArrayLike) -> Array:
        """H-side overhang, m (held at ``W(T)`` for ``t > T`` and ``C1`` for ``t < 0``)."""
        tc = np.clip(np.asarray(t, dtype=float), 0.0, self.T)
        return self.C1 - self.C2 / self.T * (
            tc - self.T / (2 * np.pi) * np.sin(2 * np.pi * tc / self.T)
        )

    def Wd(self, t: ArrayLike) -> Array:
        """dW/dt, m/s."""
        t = np.asarray(t, dtype=float)
        v = -self.C2 / self.T * (1.0 - np.cos(2 * np.pi * t / self.T))
        return np.where((t >= 0) & (t <= self.T), v, 0.0)

    def Wdd(self, t: ArrayLike) -> Array:
        """d2W/dt2, m/s^2."""
        t = np.asarray(t, dtype=float)
        a = -self.C2 / self.T * (2 * np.pi / self.T) * np.sin(2 * np.pi * t / self.T)
        return np.where((t >= 0) & (t <= self.T), a, 0.0)


SLOW_PUSH = SlidingBeamCase("slow push", C1=0.725, C2=0.7, T=3.5, tracked_end="H")
FAST_PUSH = SlidingBeamCase("fast push", C1=0.725, C2=0.7, T=0.7, tracked_end="H")
FAST_PULL = SlidingBeamCase("fast pull", C1=0.025, C2=-0.7, T=0.7, tracked_end="E")
CASES = {"slow_push": SLOW_PUSH, "fast_push": FAST_PUSH, "fast_pull": FAST_PULL}


class SlidingBeamModel:
    """FE model of the sliding beam; :meth:`problem` gives the :class:`DAEProblem`."""

    def __init__(self, case: SlidingBeamCase, n_elements: int = 4, axial_shortening: bool = True):
        self.case, self.n, self.axial_shortening = case, int(n_elements), bool(axial_shortening)
        c = case
        lo, hi = sorted((float(c.W(0.0)), float(c.W(c.T))))
        if not (c.D > 0 and lo >= 0.0 and hi <= c.L - c.D):
            raise ValueError(
                f"case {c.name!r}: supports leave the beam (W in [{lo}, {hi}] m, "
                f"need 0 <= W <= L - D = {c.L - c.D} m)"
            )
        mats = assemble_beam(self.n, c.L, c.rho, c.EI)
        self.M, self.K, self.le = mats.M, mats.K, mats.element_length
        self.S0 = mats.S0
        self.ndof = self.M.shape[0]
        x = mats.node_x
        unit_force = c.rho * x if c.driven_end == "H" else -c.rho * (c.L - x)  # F per unit Wdd
        self.G = assemble_geometric_stiffness(self.n, c.L, unit_force)
        self.tip_dof = 0 if c.tracked_end == "E" else 2 * self.n
        self._cache_t: float | None = None

    def support_positions(self, t: float) -> tuple[Array, Array, Array]:
        """Material positions of the two supports (m) and their first/second time derivatives."""
        c = self.case
        W, Wd, Wdd = float(c.W(t)), float(c.Wd(t)), float(c.Wdd(t))
        return (np.array([c.L - c.D - W, c.L - W]), np.array([-Wd, -Wd]), np.array([-Wdd, -Wdd]))

    def _rows(self, t: float) -> tuple[Array, Array, Array, Array, Array, Array]:
        """Rows of w, w', w'' at the supports, their speeds and accelerations, K + K_g (per t)."""
        if self._cache_t != t:
            xs, xsd, xsdd = self.support_positions(t)
            R = np.zeros((3, 2, self.ndof))
            located = [locate(float(x), self.n, self.case.L) for x in xs]
            zetas = np.array([z for _, z in located])
            for d in range(3):
                H = hermite_shape(zetas, self.le, d)
                for k, (j, _) in enumerate(located):
                    R[d, k, 2 * j : 2 * j + 4] = H[k]
            Kt = self.K + float(self.case.Wdd(t)) * self.G if self.axial_shortening else self.K
            self._cache = (R[0], R[1], R[2], xsd, xsdd, Kt)
            self._cache_t = t
        return self._cache

    def stiffness(self, t: float) -> Array:
        """``K + K_g(t)`` (``K`` alone without axial shortening), N/m-type units."""
        return self._rows(t)[5]

    def problem(self) -> DAEProblem:
        """The constrained equations of motion as a linear :class:`DAEProblem`."""
        zeros = np.zeros((self.ndof, self.ndof))

        def phi(q: Array, t: float) -> Array:
            return self._rows(t)[0] @ q

        def phi_q(q: Array, t: float) -> Array:
            return self._rows(t)[0]

        def phi_t(q: Array, t: float) -> Array:
            _, R1, _, xsd, _, _ = self._rows(t)
            return xsd * (R1 @ q)

        def h_q(q: Array, qd: Array, t: float) -> Array:
            _, R1, R2, xsd, xsdd, _ = self._rows(t)
            return -((xsd**2)[:, None] * R2 + xsdd[:, None] * R1)

        def h_qd(q: Array, qd: Array, t: float) -> Array:
            _, R1, _, xsd, _, _ = self._rows(t)
            return -2.0 * xsd[:, None] * R1

        def h(q: Array, qd: Array, t: float) -> Array:
            return h_q(q, qd, t) @ q + h_qd(q, qd, t) @ qd

        return DAEProblem(
            n_q=self.ndof,
            n_c=2,
            mass=lambda q, t: self.M,
            force=lambda q, qd, t: -(self.stiffness(t) @ q),
            phi=phi,
            phi_q=phi_q,
            phi_t=phi_t,
            h=h,
            force_q=lambda q, qd, t: -self.stiffness(t),
            force_qd=lambda q, qd, t: zeros,
            h_q=h_q,
            h_qd=h_qd,
            linear=True,
        )

    def initial_shape(self) -> Array:
        """Static deflection under a uniform load with the t = 0 supports, scaled to the tip value.

        Solves ``K q + A^T lam = int N dx`` (unit load), ``A q = 0``, then scales
        ``q`` so that the tracked end deflects ``case.tip_deflection``.
        """
        A = self._rows(0.0)[0]
        n = self.ndof
        S = np.zeros((n + 2, n + 2))
        S[:n, :n], S[:n, n:], S[n:, :n] = self.K, A.T, A
        q = np.linalg.solve(S, np.concatenate([self.S0 / self.case.rho, np.zeros(2)]))[:n]
        return q * (self.case.tip_deflection / q[self.tip_dof])


@dataclass(frozen=True)
class SlidingBeamResult:
    """Response of :func:`simulate_sliding_beam`.

    ``t`` (s), ``W`` (m), ``tip_y`` = transverse displacement of the tracked end (m),
    ``q`` nodal dofs (m, rad), ``lam`` support forces (N, sign of the multipliers),
    ``phi_violation`` (m) and ``phidot_violation`` (m/s) max over the two supports,
    ``wall_time`` (s) of the integration.
    """

    case: SlidingBeamCase
    n_elements: int
    axial_shortening: bool
    dt: float
    t: Array
    W: Array
    tip_y: Array
    q: Array
    lam: Array
    phi_violation: Array
    phidot_violation: Array
    wall_time: float


DEFAULT_DT = 1e-3


def simulate_sliding_beam(
    case: SlidingBeamCase,
    n_elements: int = 4,
    dt: float = DEFAULT_DT,
    duration: float | None = None,
    gamma: float = 5.0,
    beta: float = 5.0,
    alpha: float = 0.25,
    delta: float = 0.5,
    axial_shortening: bool = True,
    max_violation: float = 1e-3,
) -> SlidingBeamResult:
    """Simulate one case with Newmark + Baumgarte (paper: 4 elements, gamma = beta = 5).

    Parameters
    ----------
    case
        E.g. :data:`SLOW_PUSH`, :data:`FAST_PUSH`, :data:`FAST_PULL`.
    n_elements
        Equal Hermite elements over the whole beam.
    dt, duration
        Time step and simulated time, s (``duration`` defaults to ``max(T, 1 s)``).
    gamma, beta, alpha, delta
        Baumgarte and Newmark parameters (see :mod:`flexctrl.dynamics.fem.newmark_dae`).
    axial_shortening
        Include the geometric stiffness of the inertial axial force.
    max_violation
        Bound (m) on the position-level constraint violation; exceeding it raises
        :class:`~flexctrl.dynamics.fem.newmark_dae.ConstraintViolationError`.
    """
    model = SlidingBeamModel(case, n_elements, axial_shortening)
    t_end = max(case.T, 1.0) if duration is None else float(duration)
    q0 = model.initial_shape()
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
    return SlidingBeamResult(
        case=case,
        n_elements=model.n,
        axial_shortening=model.axial_shortening,
        dt=res.dt,
        t=res.t,
        W=case.W(res.t),
        tip_y=res.q[:, model.tip_dof],
        q=res.q,
        lam=res.lam,
        phi_violation=res.phi_violation,
        phidot_violation=res.phidot_violation,
        wall_time=res.wall_time,
    )
