"""Revolute-prismatic arm: a flexible link sliding through a rotating rigid housing (Pan et al. 1990, Figs 1, 4).

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
    :func:`flexctrl.sim.newmark_dae.simulate` (Newmark + Baumgarte, Eqs 44-56); the
    problem is linear (``DAEProblem.linear``).

Full coupling (Eq 43; :class:`RPArmFullModel`, :func:`simulate_rp_arm_full`)
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
    are exactly the partial-coupling equations above, Pan's ``K_g`` included (the ``- W' qd.Gs q``
    and ``- theta'^2 ... Gs`` terms produce it), which a test checks; unlike Pan's ``K_g`` with
    the nominal axial force, the shortening here stays a conservative part of ``T``, so
    ``M`` is symmetric and the free arm conserves ``T + V``.  The supports ``w(L - W - d_k) = 0``
    now depend on the unknown ``W``: ``Phi_z = (R0, 0, -R1 q)``, ``h = 2 W' R1 qd - W'^2 R2 q``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexctrl.beam.elements import assemble_beam, assemble_geometric_stiffness, hermite_shape, locate
from flexctrl.errors import SimulationError, SpecError
from flexctrl.sim.newmark_dae import DAEProblem, simulate
from flexctrl.spec.overrides import apply_overrides
from flexctrl.spec.reader import TableReader, read_toml

Array = NDArray[np.float64]
ENDS = ("E", "H")
INITIAL = ("rest", "static_load")


@dataclass(frozen=True)
class RPArmSpec:
    """An R-P arm (``models/rp_arm.toml``); SI units.

    Attributes
    ----------
    length, mass_per_length, EI
        Sliding link: m, kg/m, N m^2.
    support_inner, support_outer
        Radii of the two bilateral supports from the base axis, m.
    payload_mass
        Point mass at the tip H, kg.
    gravity
        Gravity in the plane of motion, world frame, m/s^2.
    hub_inertia, carriage_mass
        Housing and rotor inertia about joint 1 (kg m^2) and the mass of the axial
        drive at E (kg): not used by the prescribed-motion model, recorded for
        torque/force estimates and full coupling.
    """

    name: str
    length: float
    mass_per_length: float
    EI: float
    support_inner: float
    support_outer: float
    payload_mass: float = 0.0
    gravity: tuple[float, float] = (0.0, 0.0)
    hub_inertia: float = 0.0
    carriage_mass: float = 0.0
    source: str = ""
    notes: str = ""

    @property
    def D(self) -> float:
        """Support spacing, m."""
        return self.support_outer - self.support_inner


def rp_arm_from_document(document: dict, source: str) -> RPArmSpec:
    """Validate a parsed ``rp_arm`` model document (layout: ``models/rp_arm.toml``)."""
    r = TableReader(document, source)
    r.string("kind", "rp_arm", choices=("rp_arm",))
    link = r.table_of("link")
    length = link.positive("length", unit="m")
    rho = link.positive("mass_per_length", unit="kg/m")
    EI = link.positive("EI", unit="N m^2")
    link.string("source", "")
    link.finish()
    housing = r.table_of("housing")
    r1 = housing.nonnegative("support_inner", unit="m")
    r2 = housing.positive("support_outer", unit="m")
    housing.string("source", "")
    if not r2 > r1:
        raise housing.error("support_outer", f"value {r2!r} is not beyond support_inner = {r1!r}; allowed: > {r1} m")
    if r2 - r1 >= length:
        raise housing.error("support_outer", f"support spacing {r2 - r1:g} m leaves no stroke on a {length:g} m link; "
                                             f"allowed: spacing < {length} m")
    housing.finish()
    base = r.table_of("base", {})
    hub_inertia = base.nonnegative("hub_inertia", 0.0, unit="kg m^2")
    base.string("source", "")
    base.finish()
    carriage = r.table_of("carriage", {})
    carriage_mass = carriage.nonnegative("mass", 0.0, unit="kg")
    carriage.string("source", "")
    carriage.finish()
    payload = r.table_of("payload", {})
    m_t = payload.nonnegative("mass", 0.0, unit="kg")
    payload.string("source", "")
    payload.finish()
    gravity = r.numbers("gravity", [0.0, 0.0], length=2, unit="m/s^2")
    spec = RPArmSpec(name=r.string("name", Path(source).stem), length=length, mass_per_length=rho, EI=EI,
                     support_inner=r1, support_outer=r2, payload_mass=m_t, gravity=(gravity[0], gravity[1]),
                     hub_inertia=hub_inertia, carriage_mass=carriage_mass, source=source,
                     notes=r.string("notes", ""))
    r.finish()
    return spec


def load_rp_arm(path: str | Path, overrides: Iterable[str] = ()) -> RPArmSpec:
    """Load and validate ``models/rp_arm.toml`` (``overrides``: ``KEY=VALUE`` strings)."""
    document = apply_overrides(read_toml(path), overrides, source=f"{path} (--set)")
    return rp_arm_from_document(document, str(path))


def _check_elements(n_elements: object, key: str = "n_elements") -> None:
    if isinstance(n_elements, bool) or not isinstance(n_elements, (int, np.integer)) or not 1 <= n_elements <= 256:
        raise SpecError(f"value {n_elements!r} is not allowed; allowed: an integer from 1 to 256", key=key)


def point_rows(xs: ArrayLike, n_elements: int, length: float, max_derivative: int = 2) -> Array:
    """Rows ``R[d, k]`` with ``w^(d)(x_k) = R[d, k] @ q`` (``d = 0..max_derivative``) on a uniform mesh
    of ``n_elements`` Hermite elements over ``length`` (m); each row holds the shape functions of the
    element containing ``x_k`` (an interior node belongs to the element on its right)."""
    xs = np.atleast_1d(np.asarray(xs, dtype=float))
    le = length / n_elements
    R = np.zeros((max_derivative + 1, xs.size, 2 * (n_elements + 1)))
    located = [locate(float(x), n_elements, length) for x in xs]
    zetas = np.array([z for _, z in located])
    for d in range(max_derivative + 1):
        H = hermite_shape(zetas, le, d)
        for k, (j, _) in enumerate(located):
            R[d, k, 2 * j:2 * j + 4] = H[k]
    return R


def _profile(t: ArrayLike, T: float, derivative: int) -> Array:
    """Eq 57's unit rest-to-rest profile ``s(t) = t/T - sin(2 pi t/T)/(2 pi)`` (held outside [0, T])."""
    t = np.asarray(t, dtype=float)
    w = 2 * np.pi / T
    tc = np.clip(t, 0.0, T)
    if derivative == 0:
        return tc / T - np.sin(w * tc) / (2 * np.pi)
    inside = (t >= 0) & (t <= T)
    if derivative == 1:
        return np.where(inside, (1.0 - np.cos(w * t)) / T, 0.0)
    return np.where(inside, w * np.sin(w * t) / T, 0.0)


@dataclass(frozen=True)
class RPMotion:
    """Prescribed rigid motion: ``W(t) = C1 - C2 s(t)`` (m), ``theta(t) = theta0 + dtheta s(t)`` (rad).

    ``s`` is Eq 57's profile over ``T`` seconds; ``C2 < 0`` extends the link.
    """

    C1: float
    C2: float
    T: float
    theta0: float = 0.0
    dtheta: float = 0.0

    def W(self, t: ArrayLike) -> Array:
        """Overhang beyond the outer support, m."""
        return self.C1 - self.C2 * _profile(t, self.T, 0)

    def Wd(self, t: ArrayLike) -> Array:
        return -self.C2 * _profile(t, self.T, 1)

    def Wdd(self, t: ArrayLike) -> Array:
        return -self.C2 * _profile(t, self.T, 2)

    def theta(self, t: ArrayLike) -> Array:
        """Housing angle, rad."""
        return self.theta0 + self.dtheta * _profile(t, self.T, 0)

    def thetad(self, t: ArrayLike) -> Array:
        return self.dtheta * _profile(t, self.T, 1)

    def thetadd(self, t: ArrayLike) -> Array:
        return self.dtheta * _profile(t, self.T, 2)


class FrameLink:
    """One uniform link of Hermite elements in a frame that turns with ``theta`` and whose origin
    (the link's material point ``x = 0``) sits on the frame's axis at radius ``r_E(t)``.

    Holds the constant matrices (``M`` with the payload on the tip ``w``, ``K``, ``S0 = int rho N``,
    ``S1 = int rho x N`` and the geometric-stiffness pieces ``G_c, G_1, G_2`` for ``F = 1, x, x^2``)
    and forms the time-varying terms of the partially coupled equations (module docstring)::

        M qdd + (K + K_g - theta'^2 M) q = f,
        f = -int rho N^T (theta'' (r_E + x) + 2 theta' r_E' - g_perp) (+ payload at x = L).

    Shared by :class:`RPArmModel` and :mod:`flexctrl.dynamics.fem.telescoping`.
    """

    def __init__(self, n_elements: int, length: float, mass_per_length: float, EI: float, payload_mass: float = 0.0):
        self.n, self.length, self.rho, self.payload_mass = int(n_elements), float(length), float(mass_per_length), \
            float(payload_mass)
        mats = assemble_beam(self.n, length, mass_per_length, EI)
        self.le, self.ndof = mats.element_length, mats.M.shape[0]
        self.M, self.K = mats.M.copy(), mats.K
        self.M_link = mats.M  # without the payload
        self.S0, self.S1 = mats.S0, mats.S1  # int rho N, int rho x N
        self.tip = 2 * self.n  # dof of w(L)
        if payload_mass:
            self.M[self.tip, self.tip] += payload_mass
        # K_g = c0 G_c + c1 G_1 + c2 G_2 for F = c0 + c1 x + c2 x^2 (exact: F is at most quadratic)
        self.G_c = assemble_geometric_stiffness(self.n, length, lambda z: np.ones_like(z))
        self.G_1 = assemble_geometric_stiffness(self.n, length, lambda z: z)
        self.G_2 = assemble_geometric_stiffness(self.n, length, lambda z: z * z)

    def force_coefficients(self, r: dict[str, float], driven_end: str) -> tuple[float, float, float]:
        """``(c0, c1, c2)`` of the rigid-motion axial force ``F = c0 + c1 x + c2 x^2`` (N, tension positive).

        ``r`` holds ``rE, rEd, rEdd`` (m, m/s, m/s^2), ``thd`` (rad/s), ``g_ax`` (m/s^2).  Driven at E
        (the reaction of the whole link and payload enters at ``x = 0``): ``F(x) = -int_x^L rho a~ -
        m_t a~(L)``; driven at H: ``F(x) = int_0^x rho a~``; ``a~ = r_E'' - theta'^2 (r_E + x) - g_ax``.
        """
        rho, L, m_t = self.rho, self.length, self.payload_mass
        # a~(x) = b0 - w2 x  with b0 = rE'' - th'^2 rE - g_ax, w2 = th'^2
        b0 = r["rEdd"] - r["thd"] ** 2 * r["rE"] - r["g_ax"]
        w2 = r["thd"] ** 2
        if driven_end == "E":  # F = -int_x^L rho a~ - m_t a~(L)
            c0 = -rho * (b0 * L - 0.5 * w2 * L * L) - m_t * (b0 - w2 * L)
            return c0, rho * b0, -0.5 * rho * w2
        return 0.0, rho * b0, -0.5 * rho * w2  # F = int_0^x rho a~

    def terms(self, r: dict[str, float], driven_end: str, axial_shortening: bool) -> tuple[Array, Array]:
        """``(K + K_g - theta'^2 M, f)`` for the rigid state ``r`` (see :meth:`force_coefficients`;
        also ``thdd`` in rad/s^2 and ``g_perp`` in m/s^2)."""
        Kt = self.K - r["thd"] ** 2 * self.M
        if axial_shortening:
            c0, c1, c2 = self.force_coefficients(r, driven_end)
            Kt = Kt + c0 * self.G_c + c1 * self.G_1 + c2 * self.G_2
        a0 = r["thdd"] * r["rE"] + 2.0 * r["thd"] * r["rEd"]  # a_perp(x) = a0 + thdd x
        f = -(a0 - r["g_perp"]) * self.S0 - r["thdd"] * self.S1
        if self.payload_mass:
            f[self.tip] -= self.payload_mass * (a0 + r["thdd"] * self.length - r["g_perp"])
        return Kt, f


class RPArmModel:
    """FE model of the sliding link in the rotating housing; :meth:`problem` gives the :class:`DAEProblem`."""

    def __init__(self, spec: RPArmSpec, motion: RPMotion, n_elements: int = 8, *, axial_shortening: bool = True,
                 driven_end: Literal["E", "H"] = "E"):
        if driven_end not in ENDS:
            raise SpecError(f"value {driven_end!r} is not allowed; allowed: 'E', 'H'", key="driven_end")
        _check_elements(n_elements)
        self.spec, self.motion, self.n = spec, motion, int(n_elements)
        self.axial_shortening, self.driven_end = bool(axial_shortening), driven_end
        s, L = spec, spec.length
        lo, hi = sorted((float(motion.W(0.0)), float(motion.W(motion.T))))
        if not (lo >= 0.0 and hi <= L - s.D):
            raise SpecError(f"the overhang W runs over [{lo:g}, {hi:g}] m; allowed: within [0, L - D] = "
                            f"[0, {L - s.D:g}] m so that both supports stay on the link", key="C1")
        self.link = link = FrameLink(self.n, L, s.mass_per_length, s.EI, s.payload_mass)
        self.le, self.ndof, self.M, self.K = link.le, link.ndof, link.M, link.K
        self.S0, self.S1, self.tip = link.S0, link.S1, link.tip
        self.G_c, self.G_1, self.G_2 = link.G_c, link.G_1, link.G_2
        self._cache_t: float | None = None

    # -- rigid motion -------------------------------------------------------------------
    def rigid(self, t: float) -> dict[str, float]:
        """``r_E`` and its rates (m, m/s, m/s^2), ``theta`` and its rates, gravity components in the frame."""
        m, s = self.motion, self.spec
        th = float(m.theta(t))
        c, sn = math.cos(th), math.sin(th)
        gx, gy = s.gravity
        return {"rE": s.support_outer - s.length + float(m.W(t)), "rEd": float(m.Wd(t)), "rEdd": float(m.Wdd(t)),
                "th": th, "thd": float(m.thetad(t)), "thdd": float(m.thetadd(t)),
                "g_ax": gx * c + gy * sn, "g_perp": -gx * sn + gy * c}

    def axial_force(self, t: float, x: ArrayLike) -> Array:
        """Axial force of the rigid motion (N, tension positive) at material points ``x`` (m)."""
        c0, c1, c2 = self._force_coefficients(t)
        x = np.asarray(x, dtype=float)
        return c0 + c1 * x + c2 * x * x

    def _force_coefficients(self, t: float) -> tuple[float, float, float]:
        return self.link.force_coefficients(self.rigid(t), self.driven_end)

    def support_positions(self, t: float) -> tuple[Array, Array, Array]:
        """Material positions of the supports (m) and their first/second time derivatives."""
        m, s = self.motion, self.spec
        W, Wd, Wdd = float(m.W(t)), float(m.Wd(t)), float(m.Wdd(t))
        return (np.array([s.length - s.D - W, s.length - W]), np.array([-Wd, -Wd]), np.array([-Wdd, -Wdd]))

    def _rows(self, t: float):
        if self._cache_t != t:
            xs, xsd, xsdd = self.support_positions(t)
            R = np.zeros((3, 2, self.ndof))
            located = [locate(float(x), self.n, self.spec.length) for x in xs]
            zetas = np.array([z for _, z in located])
            for d in range(3):
                H = hermite_shape(zetas, self.le, d)
                for k, (j, _) in enumerate(located):
                    R[d, k, 2 * j:2 * j + 4] = H[k]
            Kt, f = self.link.terms(self.rigid(t), self.driven_end, self.axial_shortening)
            self._cache = (R[0], R[1], R[2], xsd, xsdd, Kt, f)
            self._cache_t = t
        return self._cache

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
            n_q=self.ndof, n_c=2, mass=lambda q, t: self.M,
            force=lambda q, qd, t: self.load(t) - self.stiffness(t) @ q,
            phi=lambda q, t: self._rows(t)[0] @ q,
            phi_q=lambda q, t: self._rows(t)[0],
            phi_t=lambda q, t: self._rows(t)[3] * (self._rows(t)[1] @ q),
            h=lambda q, qd, t: h_q(q, qd, t) @ q + h_qd(q, qd, t) @ qd,
            force_q=lambda q, qd, t: -self.stiffness(t), force_qd=lambda q, qd, t: zeros,
            h_q=h_q, h_qd=h_qd, linear=True)

    def initial_shape(self, kind: Literal["rest", "static_load"] = "rest", tip_deflection: float = 0.01,
                      tracked_end: Literal["E", "H"] = "H") -> Array:
        """Initial nodal values: zero (``"rest"``), or the static deflection under a uniform load with
        the t = 0 supports, scaled so that ``tracked_end`` deflects ``tip_deflection`` (m)."""
        if kind == "rest":
            return np.zeros(self.ndof)
        if kind != "static_load":
            raise SpecError(f"value {kind!r} is not allowed; allowed: {', '.join(map(repr, INITIAL))}", key="initial")
        A = self._rows(0.0)[0]
        n = self.ndof
        S = np.zeros((n + 2, n + 2))
        S[:n, :n], S[:n, n:], S[n:, :n] = self.K, A.T, A
        q = np.linalg.solve(S, np.concatenate([self.S0 / self.spec.mass_per_length, np.zeros(2)]))[:n]
        dof = 0 if tracked_end == "E" else self.tip
        return q * (tip_deflection / q[dof])

    def vibration_energy(self, q: Array, qd: Array) -> float:
        """``1/2 qd^T M qd + 1/2 q^T K q`` (J): kinetic energy relative to the frame plus strain energy."""
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


def simulate_rp_arm(spec: RPArmSpec, motion: RPMotion, n_elements: int = 8, dt: float = 1e-3,
                    duration: float | None = None, *, gamma: float = 5.0, beta: float = 5.0, alpha: float = 0.25,
                    delta: float = 0.5, axial_shortening: bool = True, driven_end: Literal["E", "H"] = "E",
                    tracked_end: Literal["E", "H"] = "H", initial: Literal["rest", "static_load"] = "rest",
                    tip_deflection: float = 0.01, max_violation: float = 1e-3) -> RPArmResult:
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
        raise SpecError(f"value {tracked_end!r} is not allowed; allowed: 'E', 'H'", key="tracked_end")
    model = RPArmModel(spec, motion, n_elements, axial_shortening=axial_shortening, driven_end=driven_end)
    t_end = max(motion.T, 1.0) if duration is None else float(duration)
    q0 = model.initial_shape(initial, tip_deflection, tracked_end)
    res = simulate(model.problem(), q0, np.zeros_like(q0), t_end, dt, gamma=gamma, beta=beta, alpha=alpha,
                   delta=delta, max_violation=max_violation)
    dof = 0 if tracked_end == "E" else model.tip
    theta = motion.theta(res.t)
    radius = spec.support_outer + motion.W(res.t)  # r_E + L
    w_tip = res.q[:, model.tip]
    c, s = np.cos(theta), np.sin(theta)
    tip_world = np.stack([c * radius - s * w_tip, s * radius + c * w_tip], axis=1)
    return RPArmResult(model=model, dt=res.dt, t=res.t, W=motion.W(res.t), theta=theta, tip_y=res.q[:, dof],
                       tip_world=tip_world, q=res.q, qd=res.qd, lam=res.lam, phi_violation=res.phi_violation,
                       phidot_violation=res.phidot_violation, wall_time=res.wall_time)


# =====================================================================================================
# Full coupling (Eq 43): theta and W are unknowns, driven by a joint torque and an axial force
# =====================================================================================================
@dataclass(frozen=True)
class RPForces:
    """Prescribed actuator inputs for full coupling (Eq 43) and the initial rigid state.

    ``torque(t)`` (N m) acts on joint 1 (housing angle ``theta``), ``force(t)`` (N) is the axial
    drive on the carriage at E (positive extends, increases ``W``).  ``theta0`` (rad), ``W0`` (m),
    ``thetad0`` (rad/s), ``Wd0`` (m/s): initial rigid state; the link starts undeformed.
    """

    torque: Callable[[float], float]
    force: Callable[[float], float]
    theta0: float = 0.0
    W0: float = 0.3
    thetad0: float = 0.0
    Wd0: float = 0.0

    @classmethod
    def sine(cls, torque_amplitude: float, force_amplitude: float, T: float, **initial: float) -> "RPForces":
        """One full sine period over ``[0, T]`` (s), zero afterwards: ``A sin(2 pi t / T)`` (N m and N)."""
        if not T > 0:
            raise SpecError(f"value {T!r} is not allowed; allowed: T > 0 s", key="T")

        def shape(a: float) -> Callable[[float], float]:
            return lambda t: a * math.sin(2 * math.pi * t / T) if 0.0 <= t <= T else 0.0

        return cls(torque=shape(torque_amplitude), force=shape(force_amplitude), **initial)

    @classmethod
    def from_samples(cls, t: ArrayLike, torque: ArrayLike, force: ArrayLike, **initial: float) -> "RPForces":
        """Inputs interpolated linearly between samples (s, N m, N), e.g. the multipliers of a motion run."""
        t, tau, F = (np.asarray(a, dtype=float).copy() for a in (t, torque, force))
        return cls(torque=lambda s: float(np.interp(s, t, tau)), force=lambda s: float(np.interp(s, t, F)),
                   **initial)


def _support_range_error(W: float, spec: RPArmSpec, t: float) -> SimulationError:
    return SimulationError(f"at t = {t:.6g} s the overhang W = {W:.6g} m left [0, L - D] = "
                           f"[0, {spec.length - spec.D:g}] m: a support slid off the link (full coupling; "
                           "reduce the axial force or the duration)")


class RPArmFullModel:
    """The R-P arm with the nominal joint coordinates among the unknowns (full coupling, Eq 43).

    Coordinates ``z = (q, theta, W)``: the ``2 (N + 1)`` nodal ``(w, w')`` of the sliding link, the
    housing angle (rad) and the overhang ``W`` (m) beyond the outer support.  ``M(z)``, the velocity
    terms and the generalised forces come from the Lagrangian by CasADi automatic differentiation
    (module docstring of :mod:`flexctrl.dynamics.fem.rp_arm`, section "Full coupling"); the support
    constraints ``w(L - W - d_k) = 0`` and their derivatives are formed in numpy, because the row
    follows the support from element to element as ``W`` changes.

    ``drive``: an :class:`RPForces` (torque and force prescribed) or an :class:`RPMotion`; the latter
    adds the constraints ``theta - theta(t) = 0`` and ``W - W(t) = 0`` whose multipliers are minus
    the joint torque and axial force the motion needs.
    """

    def __init__(self, spec: RPArmSpec, drive: "RPForces | RPMotion", n_elements: int = 8, *,
                 axial_shortening: bool = True):
        import casadi as ca

        _check_elements(n_elements)
        if not isinstance(drive, (RPForces, RPMotion)):
            raise SpecError(f"value {drive!r} is not allowed; allowed: an RPForces or an RPMotion", key="drive")
        self.spec, self.drive, self.n = spec, drive, int(n_elements)
        self.axial_shortening = bool(axial_shortening)
        self.motion_driven = isinstance(drive, RPMotion)
        s, L = spec, spec.length
        W0 = float(drive.W(0.0)) if self.motion_driven else float(drive.W0)
        if not 0.0 <= W0 <= L - s.D:
            raise SpecError(f"value W(0) = {W0!r} m is not allowed; allowed: within [0, L - D] = [0, {L - s.D:g}] m",
                            key="W0" if not self.motion_driven else "C1")
        link = FrameLink(self.n, L, s.mass_per_length, s.EI)
        self.link, self.le, self.ne = link, link.le, link.ndof
        self.ith, self.iW, self.nz = self.ne, self.ne + 1, self.ne + 2
        self.tip = link.tip
        self.n_joint_rows = 2 if self.motion_driven else 0
        rho, m_t, m_c, J_h = s.mass_per_length, s.payload_mass, s.carriage_mass, s.hub_inertia
        sh = 1.0 if self.axial_shortening else 0.0
        Gs = rho * (L * link.G_c - link.G_1)  # int rho s dx = 1/2 q Gs q
        Gx = rho * (0.5 * L * L * link.G_c - 0.5 * link.G_2)  # int rho (rE + x) s dx = 1/2 q (rE Gs + Gx) q

        z, zd = ca.SX.sym("z", self.nz), ca.SX.sym("zd", self.nz)
        q, th, W = z[:self.ne], z[self.ith], z[self.iW]
        qd, thd, Wd = zd[:self.ne], zd[self.ith], zd[self.iW]
        DM = ca.DM
        Ml, K, S0, S1, Gc = DM(link.M_link), DM(link.K), DM(link.S0), DM(link.S1), DM(link.G_c)
        rE = s.support_outer - L + W
        quad = lambda A, a, b: ca.dot(a, ca.mtimes(A, b))  # noqa: E731
        wL, wdL = q[self.tip], qd[self.tip]
        sL, sdL = 0.5 * sh * quad(Gc, q, q), sh * quad(Gc, qd, q)
        T_link = (0.5 * rho * L * Wd**2 - sh * Wd * quad(DM(Gs), qd, q) - Wd * thd * ca.dot(DM(S0), q)
                  + 0.5 * thd**2 * quad(Ml, q, q) + 0.5 * quad(Ml, qd, qd) + thd * ca.dot(qd, rE * S0 + S1)
                  + 0.5 * thd**2 * rho * (L * rE**2 + L**2 * rE + L**3 / 3.0)
                  - 0.5 * sh * thd**2 * (rE * quad(DM(Gs), q, q) + quad(DM(Gx), q, q)))
        T_payload = 0.5 * m_t * (Wd**2 - 2 * Wd * sdL - 2 * Wd * thd * wL + thd**2 * wL**2 + wdL**2
                                 + 2 * thd * wdL * (rE + L) + thd**2 * (rE + L) ** 2 - 2 * thd**2 * (rE + L) * sL)
        T = T_link + T_payload + 0.5 * J_h * thd**2 + 0.5 * m_c * (Wd**2 + rE**2 * thd**2)
        gx, gy = s.gravity
        g_ax, g_perp = gx * ca.cos(th) + gy * ca.sin(th), -gx * ca.sin(th) + gy * ca.cos(th)
        V = (0.5 * quad(K, q, q)
             - g_ax * (rho * (L * rE + 0.5 * L * L) - 0.5 * sh * quad(DM(Gs), q, q) + m_t * (rE + L - sL) + m_c * rE)
             - g_perp * (ca.dot(DM(S0), q) + m_t * wL))
        p = ca.gradient(T, zd)
        mass = ca.jacobian(p, zd)
        f = ca.gradient(T - V, z) - ca.mtimes(ca.jacobian(p, z), zd)
        self._fun = {
            "M": ca.Function("M", [z], [mass]),
            "f": ca.Function("f", [z, zd], [f]),
            "f_z": ca.Function("f_z", [z, zd], [ca.jacobian(f, z)]),
            "f_zd": ca.Function("f_zd", [z, zd], [ca.jacobian(f, zd)]),
            "energy": ca.Function("energy", [z, zd], [T, V]),
            "momentum": ca.Function("p", [z, zd], [p]),
        }
        from flexctrl.dynamics.fem.newmark import _Evaluator

        self._fast = {k: _Evaluator(self._fun[k]) for k in ("M", "f", "f_z", "f_zd")}
        self._rows_W: float | None = None

    # -- helpers --------------------------------------------------------------------------------------
    def _eval(self, name: str, *args: Array) -> Array:
        if name in self._fast:
            return self._fast[name](*args)[0]
        return np.asarray(self._fun[name](*args).full(), dtype=float)

    def mass(self, z: Array) -> Array:
        """Generalised mass ``M(z)`` (kg, kg m, kg m^2)."""
        return self._eval("M", z)

    def internal_force(self, z: Array, zd: Array) -> Array:
        """``dL/dz - (d^2 T / dzd dz) zd``: everything but the actuator inputs and constraint forces."""
        return self._eval("f", z, zd).ravel()

    def energies(self, z: Array, zd: Array) -> tuple[float, float]:
        """Kinetic and potential energy ``(T, V)``, J (``V``: strain plus gravity; zero at ``q = 0``,
        ``r_E = 0`` on the housing axis)."""
        T, V = self._fun["energy"](z, zd)
        return float(T), float(V)

    def momentum(self, z: Array, zd: Array) -> Array:
        """Generalised momenta ``dT/dzd``; entry ``ith`` is the angular momentum about joint 1 (kg m^2/s)."""
        return self._eval("momentum", z, zd).ravel()

    def inputs(self, t: float) -> tuple[float, float]:
        """Applied ``(torque, force)`` (N m, N); zero under a motion drive (the multipliers carry them)."""
        if self.motion_driven:
            return 0.0, 0.0
        return float(self.drive.torque(t)), float(self.drive.force(t))

    def support_rows(self, W: float, t: float = math.nan) -> Array:
        """``R[d, k]``: rows of ``w^(d)`` (``d = 0..3``) at the supports ``x_k = L - D - W, L - W``."""
        s = self.spec
        if not (-1e-12 <= W <= s.length - s.D + 1e-12):
            raise _support_range_error(W, s, t)
        if self._rows_W != W:
            W = min(max(W, 0.0), s.length - s.D)
            self._rows = point_rows([s.length - s.D - W, s.length - W], self.n, s.length, 3)
            self._rows_W = W
        return self._rows

    def initial_state(self) -> tuple[Array, Array]:
        """Undeformed link at rest relative to the housing, rigid state from the drive."""
        z, zd = np.zeros(self.nz), np.zeros(self.nz)
        d = self.drive
        if self.motion_driven:
            z[self.ith], z[self.iW] = float(d.theta(0.0)), float(d.W(0.0))
            zd[self.ith], zd[self.iW] = float(d.thetad(0.0)), float(d.Wd(0.0))
        else:
            z[self.ith], z[self.iW], zd[self.ith], zd[self.iW] = d.theta0, d.W0, d.thetad0, d.Wd0
        return z, zd

    def problem(self) -> DAEProblem:
        """``M(z) zdd + Phi_z^T lam = f(z, zd) + Q(t)`` with the support (and joint) constraints."""
        ne, ith, iW, nz, nj = self.ne, self.ith, self.iW, self.nz, self.n_joint_rows
        m = 2 + nj
        d = self.drive

        def force(z: Array, zd: Array, t: float) -> Array:
            out = self.internal_force(z, zd)
            tau, F = self.inputs(t)
            out[ith] += tau
            out[iW] += F
            return out

        def phi(z: Array, t: float) -> Array:
            R = self.support_rows(z[iW], t)
            out = np.empty(m)
            out[:2] = R[0] @ z[:ne]
            if nj:
                out[2:] = z[ith] - float(d.theta(t)), z[iW] - float(d.W(t))
            return out

        def phi_q(z: Array, t: float) -> Array:
            R = self.support_rows(z[iW], t)
            J = np.zeros((m, nz))
            J[:2, :ne] = R[0]
            J[:2, iW] = -(R[1] @ z[:ne])  # d x_k / dW = -1
            if nj:
                J[2, ith] = J[3, iW] = 1.0
            return J

        def phi_t(z: Array, t: float) -> Array:
            out = np.zeros(m)
            if nj:
                out[2:] = -float(d.thetad(t)), -float(d.Wd(t))
            return out

        def h(z: Array, zd: Array, t: float) -> Array:
            R = self.support_rows(z[iW], t)
            q, qd, Wd = z[:ne], zd[:ne], zd[iW]
            out = np.zeros(m)
            out[:2] = 2 * Wd * (R[1] @ qd) - Wd**2 * (R[2] @ q)
            if nj:
                out[2:] = float(d.thetadd(t)), float(d.Wdd(t))
            return out

        def h_q(z: Array, zd: Array, t: float) -> Array:
            R = self.support_rows(z[iW], t)
            q, qd, Wd = z[:ne], zd[:ne], zd[iW]
            J = np.zeros((m, nz))
            J[:2, :ne] = -Wd**2 * R[2]
            J[:2, iW] = -2 * Wd * (R[2] @ qd) + Wd**2 * (R[3] @ q)
            return J

        def h_qd(z: Array, zd: Array, t: float) -> Array:
            R = self.support_rows(z[iW], t)
            q, qd, Wd = z[:ne], zd[:ne], zd[iW]
            J = np.zeros((m, nz))
            J[:2, :ne] = 2 * Wd * R[1]
            J[:2, iW] = 2 * (R[1] @ qd) - 2 * Wd * (R[2] @ q)
            return J

        return DAEProblem(n_q=nz, n_c=m, mass=lambda z, t: self.mass(z), force=force, phi=phi, phi_q=phi_q,
                          phi_t=phi_t, h=h, force_q=lambda z, zd, t: self._eval("f_z", z, zd),
                          force_qd=lambda z, zd, t: self._eval("f_zd", z, zd), h_q=h_q, h_qd=h_qd)


@dataclass(frozen=True)
class RPArmFullResult:
    """Response of :func:`simulate_rp_arm_full`.

    ``t`` (s); ``theta`` (rad), ``thetad`` (rad/s), ``W`` (m), ``Wd`` (m/s): the nominal joint
    coordinates, now unknowns; ``torque`` (N m) and ``force`` (N): applied (force drive) or needed
    (motion drive, minus the joint multipliers); ``q``, ``qd`` nodal values and rates; ``lam`` the
    support forces (N); ``tip_y`` transverse displacement of the tracked end in the link frame (m);
    ``tip_world`` position of H (m, axial shortening not included); violations of the support
    constraints (m, m/s); ``newton_iterations`` per step; ``wall_time`` (s); ``model``.
    """

    model: RPArmFullModel
    dt: float
    t: Array
    theta: Array
    thetad: Array
    W: Array
    Wd: Array
    torque: Array
    force: Array
    q: Array
    qd: Array
    lam: Array
    tip_y: Array
    tip_world: Array
    phi_violation: Array
    phidot_violation: Array
    newton_iterations: NDArray[np.int_]
    wall_time: float


def simulate_rp_arm_full(spec: RPArmSpec, drive: "RPForces | RPMotion", n_elements: int = 8, dt: float = 1e-3,
                         duration: float = 1.0, *, gamma: float = 5.0, beta: float = 5.0, alpha: float = 0.25,
                         delta: float = 0.5, axial_shortening: bool = True,
                         tracked_end: Literal["E", "H"] = "H", max_violation: float = 1e-3,
                         newton_tol: float = 1e-10, max_iterations: int = 30,
                         initial_q: ArrayLike | None = None) -> RPArmFullResult:
    """Simulate the fully coupled R-P arm (Eq 43) with Newmark + Baumgarte (Newton on ``z, lam``).

    Parameters
    ----------
    drive
        :class:`RPForces` (joint torque and axial force prescribed, ``theta`` and ``W`` solved for) or
        :class:`RPMotion` (both prescribed through constraints; reports the torque and force needed).
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
        Newton stopping rule of :func:`flexctrl.sim.newmark_dae.simulate`.
    initial_q
        Initial nodal values (m, rad), e.g. :meth:`RPArmModel.initial_shape`; default undeformed.
        Must vanish at the supports (checked, 1e-9 m).  If the link slides (``Wd0 != 0``) the
        nodal velocities start as the smallest (mass-weighted) ones that keep the supports
        at rest on the deflected link, ``w_t(x_k) = W' w'(x_k)``, so that ``Phidot = 0``.

    Raises
    ------
    SimulationError
        A support slid off the link (``W`` left ``[0, L - D]``) or a constraint violation diverged.
    SolverError
        Newton failed to converge.
    """
    if tracked_end not in ENDS:
        raise SpecError(f"value {tracked_end!r} is not allowed; allowed: 'E', 'H'", key="tracked_end")
    model = RPArmFullModel(spec, drive, n_elements, axial_shortening=axial_shortening)
    z0, zd0 = model.initial_state()
    if initial_q is not None:
        q0 = np.asarray(initial_q, dtype=float)
        if q0.shape != (model.ne,):
            raise SpecError(f"initial_q has shape {q0.shape}; allowed: ({model.ne},)", key="initial_q")
        off = np.abs(model.support_rows(z0[model.iW])[0] @ q0).max()
        if not off <= 1e-9:
            raise SpecError(f"initial_q is {off:.3g} m off the supports; allowed: <= 1e-9 m", key="initial_q")
        z0[:model.ne] = q0
        R = model.support_rows(z0[model.iW])
        need = zd0[model.iW] * (R[1] @ q0)  # Phidot = R0 qd - W' R1 q = 0
        Minv_At = np.linalg.solve(model.link.M_link + model.spec.payload_mass * np.outer(
            np.eye(model.ne)[model.tip], np.eye(model.ne)[model.tip]), R[0].T)
        zd0[:model.ne] = Minv_At @ np.linalg.solve(R[0] @ Minv_At, need)
    res = simulate(model.problem(), z0, zd0, float(duration), dt, gamma=gamma, beta=beta, alpha=alpha, delta=delta,
                   max_violation=max_violation, newton_tol=newton_tol, max_iterations=max_iterations)
    ne, ith, iW = model.ne, model.ith, model.iW
    if model.motion_driven:
        torque, force = -res.lam[:, 2], -res.lam[:, 3]
    else:
        applied = np.array([model.inputs(t) for t in res.t])
        torque, force = applied[:, 0], applied[:, 1]
    theta, W = res.q[:, ith], res.q[:, iW]
    radius = spec.support_outer + W
    w_tip = res.q[:, model.tip]
    c, s = np.cos(theta), np.sin(theta)
    dof = 0 if tracked_end == "E" else model.tip
    # violations of the support rows only (the joint rows of a motion drive are reported via theta, W)
    vp = np.array([np.abs(model.support_rows(z[iW], t)[0] @ z[:ne]).max() for t, z in zip(res.t, res.q)])
    vv = np.array([np.abs(model.support_rows(z[iW], t)[0] @ zd[:ne] - zd[iW] * (model.support_rows(z[iW], t)[1]
                                                                                 @ z[:ne])).max()
                   for t, z, zd in zip(res.t, res.q, res.qd)])
    return RPArmFullResult(model=model, dt=res.dt, t=res.t, theta=theta, thetad=res.qd[:, ith], W=W, Wd=res.qd[:, iW],
                           torque=torque, force=force, q=res.q[:, :ne], qd=res.qd[:, :ne], lam=res.lam[:, :2],
                           tip_y=res.q[:, dof], tip_world=np.stack([c * radius - s * w_tip, s * radius + c * w_tip], 1),
                           phi_violation=vp, phidot_violation=vv, newton_iterations=res.newton_iterations,
                           wall_time=res.wall_time)
