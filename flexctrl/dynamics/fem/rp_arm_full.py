"""Revolute-prismatic arm, full coupling (Pan et al. 1990, Eq 43): ``theta`` and ``W`` among the unknowns.

The arm, its geometry and the prescribed-motion model (partial coupling, Eq 42) are described in
:mod:`flexctrl.dynamics.fem.rp_arm`; the description is :class:`~flexctrl.spec.fem_models.RPArmSpec`.

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
    are exactly the partial-coupling equations of :mod:`~flexctrl.dynamics.fem.rp_arm`, Pan's ``K_g`` included (the ``- W' qd.Gs q``
    and ``- theta'^2 ... Gs`` terms produce it), which a test checks; unlike Pan's ``K_g`` with
    the nominal axial force, the shortening here stays a conservative part of ``T``, so
    ``M`` is symmetric and the free arm conserves ``T + V``.  The supports ``w(L - W - d_k) = 0``
    now depend on the unknown ``W``: ``Phi_z = (R0, 0, -R1 q)``, ``h = 2 W' R1 qd - W'^2 R2 q``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexctrl.dynamics.fem.moving_frame import ENDS, FrameLink, RPMotion, check_elements, point_rows
from flexctrl.dynamics.fem.newmark_dae import DAEProblem, simulate
from flexctrl.errors import SimulationError, SpecError
from flexctrl.spec.fem_models import RPArmSpec

Array = NDArray[np.float64]


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
    (module docstring); the support constraints ``w(L - W - d_k) = 0`` and their derivatives are
    formed in numpy, because the row follows the support from element to element as ``W`` changes.

    ``drive``: an :class:`RPForces` (torque and force prescribed) or an :class:`RPMotion`; the latter
    adds the constraints ``theta - theta(t) = 0`` and ``W - W(t) = 0`` whose multipliers are minus
    the joint torque and axial force the motion needs.
    """

    def __init__(self, spec: RPArmSpec, drive: "RPForces | RPMotion", n_elements: int = 8, *,
                 axial_shortening: bool = True):
        import casadi as ca

        check_elements(n_elements)
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
        Newton stopping rule of :func:`flexctrl.dynamics.fem.newmark_dae.simulate`.
    initial_q
        Initial nodal values (m, rad), e.g. :meth:`flexctrl.dynamics.fem.rp_arm.RPArmModel.initial_shape`; default undeformed.
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
