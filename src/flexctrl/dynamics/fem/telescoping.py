"""Telescoping prismatic joint: two flexible links sliding on each other (Pan et al. 1990).

Pan et al.'s Fig 5 and Eqs 26-28.

Geometry
    Joint 1 (revolute, at the origin) turns the pair by ``theta(t)``.  The *outer* link (a
    tube, link i-1) is clamped to the hub at radius ``r0`` and reaches to its mouth at
    ``x1 = L1`` (material coordinate ``x1`` from its root).  The *inner* link (link i), material
    coordinate ``x2`` from its root E to its tip H, slides inside it.  ``W(t)`` is the overhang
    of H beyond the mouth, so E sits at the tube coordinate ``s(t) = L1 - L2 + W`` (radius
    ``r0 + s``).  Both links have Hermite elements; the outer link's root node is clamped
    (eliminated), the inner link is free except at the contacts.  ``W`` and ``theta`` follow
    Eq 57's profile (:class:`~flexctrl.dynamics.fem.moving_frame.RPMotion`), prescribed (partial
    coupling, Eq 42).

Contacts (the compatibility conditions of Eqs 26-28)
    Each contact is a bearing fixed on one link that the other link slides through:
    ``on = "outer"`` at ``x1 = a`` (e.g. the mouth, ``a = L1``) touches the inner link at
    ``x2 = a - s(t)``; ``on = "inner"`` at ``x2 = b`` (e.g. the root, ``b = 0``) touches the
    outer link at ``x1 = b + s(t)``.  So the contact points move along both links, and each
    constraint row holds the shape functions of the elements currently containing them.  Each
    contact equates the transverse displacements (Eq 26, planar, measured in the common rotating
    frame): ``w1(x1_k) - w2(x2_k) = 0``; with ``slope = true`` also the slopes (Eq 28).  Pan's
    Fig 5 states Eqs 26-28 at one point D'; a single contact with ``slope = true`` is that
    literal model (a long, stiff sleeve).  Two slope-free contacts -- the tube mouth and the
    inner root, as a real telescope is built -- is the other common reading (a bearing at each
    end of the overlap).  The two links are separate beams between contacts: the overlap is
    *not* a composite section (:func:`static_tip_deflection` gives the closed form).

Frame, loads, axial force
    Both links are measured in the frame turning with ``theta``; each has the partial-coupling
    terms of :class:`~flexctrl.dynamics.fem.moving_frame.FrameLink`: ``-theta'^2 M`` softening,
    loads ``-int rho N^T (theta'' (r + x) + 2 theta' r' - g_perp)``, and (axial shortening, Eqs
    16-18) ``K_g`` from the rigid-motion axial force.  The axial drive is anchored at the hub and
    pushes the inner link at E, so the inner link carries Eq 18 with the reaction at E, and the
    outer link only its own inertia (reaction at its clamped root).  Axial displacements are not
    modelled (Eq 26's axial component is the prescribed ``s(t)``).

Solution: Newmark + Baumgarte (:func:`flexctrl.dynamics.fem.newmark_dae.simulate`); the DAE is
linear.

Description and model file: :class:`~flexctrl.spec.fem_models.TelescopingSpec`
(``models/telescoping.toml``, read by :func:`~flexctrl.spec.fem_models.load_telescoping`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from flexctrl.dynamics.fem.moving_frame import FrameLink, RPMotion, check_elements, point_rows
from flexctrl.dynamics.fem.newmark_dae import DAEProblem, simulate
from flexctrl.errors import SpecError
from flexctrl.spec.fem_models import TelescopingSpec

Array = NDArray[np.float64]


class TelescopingModel:
    """FE model of the telescoping pair under prescribed ``theta(t)``, ``W(t)``.

    Unknowns ``q = (q1, q2)``: the outer link's nodal ``(w, w')`` without its clamped root node
    (``2 N1`` values), then the inner link's (``2 (N2 + 1)``).
    """

    def __init__(
        self,
        spec: TelescopingSpec,
        motion: RPMotion,
        n_outer: int = 8,
        n_inner: int = 8,
        *,
        axial_shortening: bool = True,
    ):
        check_elements(n_outer, "n_outer")
        check_elements(n_inner, "n_inner")
        self.spec, self.motion, self.axial_shortening = spec, motion, bool(axial_shortening)
        self.n1, self.n2 = int(n_outer), int(n_inner)
        spec.check_stroke([self.s(0.0), self.s(motion.T)])
        o, i = spec.outer, spec.inner
        self.outer = FrameLink(self.n1, o.length, o.mass_per_length, o.EI)
        self.inner = FrameLink(self.n2, i.length, i.mass_per_length, i.EI, spec.payload_mass)
        self.n_q1 = self.outer.ndof - 2
        self.ndof = self.n_q1 + self.inner.ndof
        self.i1, self.i2 = slice(0, self.n_q1), slice(self.n_q1, self.ndof)
        self.M = np.zeros((self.ndof, self.ndof))
        self.K = np.zeros((self.ndof, self.ndof))
        self.M[self.i1, self.i1], self.K[self.i1, self.i1] = (
            self.outer.M[2:, 2:],
            self.outer.K[2:, 2:],
        )
        self.M[self.i2, self.i2], self.K[self.i2, self.i2] = self.inner.M, self.inner.K
        self.orders = np.array([d for c in spec.contacts for d in ((0, 1) if c.slope else (0,))])
        self.contact_of_row = np.array(
            [k for k, c in enumerate(spec.contacts) for _ in range(1 + c.slope)]
        )
        self.n_c = self.orders.size
        self.tip = self.n_q1 + self.inner.tip  # dof of w2(L2)
        self.outer_tip = self.n_q1 - 2  # dof of w1(L1)
        self._cache_t: float | None = None

    def s(self, t: float) -> float:
        """Tube coordinate of the inner root E, m."""
        return self.spec.outer.length - self.spec.inner.length + float(self.motion.W(t))

    def rigid(self, t: float) -> tuple[dict[str, float], dict[str, float]]:
        """Rigid-motion states of the outer and inner link frames (see :meth:`FrameLink.terms`)."""
        m, sp = self.motion, self.spec
        th = float(m.theta(t))
        gx, gy = sp.gravity
        common = {
            "th": th,
            "thd": float(m.thetad(t)),
            "thdd": float(m.thetadd(t)),
            "g_ax": gx * math.cos(th) + gy * math.sin(th),
            "g_perp": -gx * math.sin(th) + gy * math.cos(th),
        }
        outer = {"rE": sp.hub_radius, "rEd": 0.0, "rEdd": 0.0, **common}
        inner = {
            "rE": sp.hub_radius + self.s(t),
            "rEd": float(m.Wd(t)),
            "rEdd": float(m.Wdd(t)),
            **common,
        }
        return outer, inner

    def contact_rows(self, t: float) -> tuple[Array, Array, Array]:
        """``(R, xd, xdd)``: the contact rows and the contact points' sliding speeds, accelerations.

        ``R[d]`` (rows x ndof) are the derivative-``d`` rows of ``w1(x1_k) - w2(x2_k)`` (or of the
        slopes for slope rows) for ``d = 0, 1, 2`` (derivatives along the links); ``xd`` and
        ``xdd`` the contact points' speeds and accelerations along the outer (column 0) and inner
        (column 1) link (m/s, m/s^2).
        """
        sp = self.spec
        x1, x2 = sp.contact_points(self.s(t))
        Wd, Wdd = float(self.motion.Wd(t)), float(self.motion.Wdd(t))
        on_inner = np.array([c.on == "inner" for c in sp.contacts], dtype=float)
        xd = np.stack([on_inner * Wd, (on_inner - 1.0) * Wd], axis=1)  # x1 = b + s or x2 = a - s
        xdd = np.stack([on_inner * Wdd, (on_inner - 1.0) * Wdd], axis=1)
        P1 = point_rows(x1, self.n1, sp.outer.length, 3)[:, :, 2:]
        P2 = point_rows(x2, self.n2, sp.inner.length, 3)
        R = np.zeros((3, self.n_c, self.ndof))
        k, d0 = self.contact_of_row, self.orders
        for d in range(3):
            R[d, :, self.i1] = P1[d0 + d, k]
            R[d, :, self.i2] = -P2[d0 + d, k]
        return R, xd[k], xdd[k]

    def _terms(self, t: float):
        if self._cache_t != t:
            R, xd, xdd = self.contact_rows(t)
            (ro, ri) = self.rigid(t)
            K1, f1 = self.outer.terms(ro, "E", self.axial_shortening)
            K2, f2 = self.inner.terms(ri, "E", self.axial_shortening)
            Kt = np.zeros((self.ndof, self.ndof))
            Kt[self.i1, self.i1], Kt[self.i2, self.i2] = K1[2:, 2:], K2
            f = np.concatenate([f1[2:], f2])
            # per link: d/dt [r(x(t)) q] = r q' + x' r' q  ->  Phi_t and the h of Eq 47
            R1, R2 = R.copy(), R.copy()  # the outer-link and the inner-link part of every row
            R1[:, :, self.i2] = 0.0
            R2[:, :, self.i1] = 0.0
            v1, v2, a1, a2 = xd[:, :1], xd[:, 1:], xdd[:, :1], xdd[:, 1:]
            phi_t_rows = v1 * R1[1] + v2 * R2[1]
            h_q = -(v1**2 * R1[2] + a1 * R1[1] + v2**2 * R2[2] + a2 * R2[1])
            h_qd = -2.0 * phi_t_rows
            self._cache = (R[0], phi_t_rows, h_q, h_qd, Kt, f)
            self._cache_t = t
        return self._cache

    def stiffness(self, t: float) -> Array:
        """``K + K_g(t) - theta'^2 M`` of both links, N/m-type units."""
        return self._terms(t)[4]

    def load(self, t: float) -> Array:
        """Generalised force of the rigid-motion inertia, gravity and payload, N and N m."""
        return self._terms(t)[5]

    def problem(self) -> DAEProblem:
        """The constrained equations of motion as a linear :class:`DAEProblem`."""
        zeros = np.zeros((self.ndof, self.ndof))
        return DAEProblem(
            n_q=self.ndof,
            n_c=self.n_c,
            mass=lambda q, t: self.M,
            force=lambda q, qd, t: self.load(t) - self.stiffness(t) @ q,
            phi=lambda q, t: self._terms(t)[0] @ q,
            phi_q=lambda q, t: self._terms(t)[0],
            phi_t=lambda q, t: self._terms(t)[1] @ q,
            h=lambda q, qd, t: self._terms(t)[2] @ q + self._terms(t)[3] @ qd,
            force_q=lambda q, qd, t: -self.stiffness(t),
            force_qd=lambda q, qd, t: zeros,
            h_q=lambda q, qd, t: self._terms(t)[2],
            h_qd=lambda q, qd, t: self._terms(t)[3],
            linear=True,
        )

    def static(self, tip_force: float, t: float = 0.0) -> tuple[Array, Array]:
        """Static deflection ``(q, lam)`` under a transverse force (N) at the inner tip H.

        The contacts at time ``t``, no frame loads: solves ``K q + Phi_q^T lam = f``,
        ``Phi_q q = 0``.
        """
        A = self._terms(t)[0]
        n, m = self.ndof, self.n_c
        S = np.zeros((n + m, n + m))
        S[:n, :n], S[:n, n:], S[n:, :n] = self.K, A.T, A
        rhs = np.zeros(n + m)
        rhs[self.tip] = tip_force
        try:
            sol = np.linalg.solve(S, rhs)
        except np.linalg.LinAlgError as exc:
            raise SpecError(
                "the contacts do not hold the inner link (singular static system); allowed: two "
                "distinct contacts or one with slope = true",
                key="contacts",
            ) from exc
        return sol[:n], sol[n:]

    def vibration_energy(self, q: Array, qd: Array) -> float:
        """``1/2 qd^T M qd + 1/2 q^T K q`` (J): kinetic energy in the frames plus strain energy."""
        return 0.5 * float(qd @ self.M @ qd) + 0.5 * float(q @ self.K @ q)


def static_tip_deflection(spec: TelescopingSpec, s: float, P: float) -> float:
    """Closed-form tip deflection (m) of the cantilevered pair under a tip force ``P`` (N), E at
    tube coordinate ``s`` (m), for the two contact layouts with a closed form.

    * mouth + root (outer at ``L1``, inner at 0, no slopes): overlap ``a = L1 - s``, overhang
      ``c = L2 - a``.  The inner link is statically determinate: ``R_mouth = P L2 / a`` and
      ``R_root = -P c / a`` act on the tube at ``L1`` and ``s``.  Tip = ``w1(L1) + (w1(L1) -
      w1(s)) c / a + P c^2 (a + c) / (3 EI2)`` (chord through the contacts plus the overhanging
      beam); ``w1`` from cantilever superposition ``F b^2 (3x - b) / 6EI`` (``x >= b``) and
      ``F x^2 (3b - x) / 6EI`` (``x <= b``).  Not a composite section: between the contacts the
      links bend independently.
    * one contact with slope (Pan's literal Eqs 26-28) at the mouth: tube cantilever with tip
      force ``P`` and moment ``P c``, inner overhang cantilevered from it:
      ``w1(L1) + w1'(L1) c + P c^3 / (3 EI2)``.

    Parameters
    ----------
    spec : TelescopingSpec
        The pair and its contact layout.
    s : float
        Tube coordinate of the inner link's end E, m.
    P : float
        Tip force, N.

    Returns
    -------
    float
        Tip deflection, m.
    """
    L1, L2, EI1, EI2 = spec.outer.length, spec.inner.length, spec.outer.EI, spec.inner.EI
    a = L1 - s
    c = L2 - a
    cs = sorted((k.on, k.at, k.slope) for k in spec.contacts)
    if cs == [("inner", 0.0, False), ("outer", L1, False)]:

        def w1(x: float, F: float, b: float) -> float:
            return F * (x * x * (3 * b - x) if x <= b else b * b * (3 * x - b)) / (6 * EI1)

        R_mouth, R_root = P * L2 / a, -P * c / a  # forces of the inner link on the tube
        w_mouth = w1(L1, R_mouth, L1) + w1(L1, R_root, s)
        w_s = w1(s, R_mouth, L1) + w1(s, R_root, s)
        return w_mouth + (w_mouth - w_s) * c / a + P * c * c * (a + c) / (3 * EI2)
    if cs == [("outer", L1, True)]:
        M = P * c
        w, slope = (
            P * L1**3 / (3 * EI1) + M * L1**2 / (2 * EI1),
            P * L1**2 / (2 * EI1) + M * L1 / EI1,
        )
        return w + slope * c + P * c**3 / (3 * EI2)
    raise SpecError(
        f"no closed form for contacts {spec.contacts}; allowed: mouth + root without slopes, "
        "or one slope contact at the mouth",
        key="contacts",
    )


@dataclass(frozen=True)
class TelescopingResult:
    """Response of :func:`simulate_telescoping`.

    ``t`` (s), ``W`` (m), ``theta`` (rad), ``tip_y``: transverse displacement of the tracked end
    of the inner link (m), ``outer_tip_y``: of the tube mouth (m), ``tip_world``: position of H
    (m, shape (T, 2)), ``q``, ``qd`` (nodal values), ``lam`` contact forces (N; N m for slope
    rows), ``phi_violation`` (m), ``phidot_violation`` (m/s), ``wall_time`` (s), ``model``.
    """

    model: TelescopingModel
    dt: float
    t: Array
    W: Array
    theta: Array
    tip_y: Array
    outer_tip_y: Array
    tip_world: Array
    q: Array
    qd: Array
    lam: Array
    phi_violation: Array
    phidot_violation: Array
    wall_time: float


def simulate_telescoping(
    spec: TelescopingSpec,
    motion: RPMotion,
    n_outer: int = 8,
    n_inner: int = 8,
    dt: float = 1e-3,
    duration: float | None = None,
    *,
    gamma: float = 5.0,
    beta: float = 5.0,
    alpha: float = 0.25,
    delta: float = 0.5,
    axial_shortening: bool = True,
    tracked_end: Literal["E", "H"] = "H",
    max_violation: float = 1e-3,
) -> TelescopingResult:
    """Simulate the telescoping pair under prescribed motion with Newmark + Baumgarte.

    Parameters
    ----------
    n_outer, n_inner
        Equal Hermite elements on the outer and inner link.
    dt, duration
        Step and simulated time, s (``duration`` defaults to ``max(T, 1 s)``).
    gamma, beta
        Baumgarte parameters (1/s, Eq 49); ``0, 0`` runs without stabilisation.
    alpha, delta
        Newmark parameters.
    axial_shortening
        Geometric stiffness of the rigid-motion axial forces (Eqs 16-18).
    tracked_end
        End of the inner link reported as ``tip_y``.
    max_violation
        Bound (m) on the position-level constraint violation (:class:`SimulationError` beyond).
    """
    if tracked_end not in ("E", "H"):
        raise SpecError(
            f"value {tracked_end!r} is not allowed; allowed: 'E', 'H'", key="tracked_end"
        )
    model = TelescopingModel(spec, motion, n_outer, n_inner, axial_shortening=axial_shortening)
    t_end = max(motion.T, 1.0) if duration is None else float(duration)
    q0 = np.zeros(model.ndof)
    start = time.perf_counter()
    res = simulate(
        model.problem(),
        q0,
        q0.copy(),
        t_end,
        dt,
        gamma=gamma,
        beta=beta,
        alpha=alpha,
        delta=delta,
        max_violation=max_violation,
    )
    dof = model.n_q1 if tracked_end == "E" else model.tip
    theta = motion.theta(res.t)
    radius = spec.hub_radius + spec.outer.length + motion.W(res.t)
    w_tip = res.q[:, model.tip]
    c, s = np.cos(theta), np.sin(theta)
    return TelescopingResult(
        model=model,
        dt=res.dt,
        t=res.t,
        W=motion.W(res.t),
        theta=theta,
        tip_y=res.q[:, dof],
        outer_tip_y=res.q[:, model.outer_tip],
        tip_world=np.stack([c * radius - s * w_tip, s * radius + c * w_tip], 1),
        q=res.q,
        qd=res.qd,
        lam=res.lam,
        phi_violation=res.phi_violation,
        phidot_violation=res.phidot_violation,
        wall_time=time.perf_counter() - start,
    )
