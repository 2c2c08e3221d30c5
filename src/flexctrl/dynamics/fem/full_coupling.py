"""Full coupling (Pan et al. 1990, Eq 43) of links sliding along a turning axis: shared parts.

The nominal joint coordinates ``theta`` (rad, joint 1) and ``W`` (m, the prismatic stroke) are
unknowns beside the nodal values; the inputs are a joint torque and an axial force.  Used by
:mod:`flexctrl.dynamics.fem.rp_arm_full` (a link in a rigid housing, supports or Pan's Fig 4 clamp)
and :mod:`flexctrl.dynamics.fem.telescoping_full` (two flexible links, Fig 5).

* :func:`link_energies`: kinetic and potential energy of one link measured in the frame turning with
  ``theta``, its root E on the axis at radius ``r_E`` moving at ``r_E'``, with the axial shortening
  ``s(x) = 1/2 int_0^x w'^2`` measured from E kept in the kinematics (the formula is in
  :mod:`flexctrl.dynamics.fem.rp_arm_full`); :func:`payload_energies` the same for a tip mass;
* :class:`SlidingFullModel`: ``M(z)``, velocity terms and gravity by CasADi differentiation of
  ``L = T - V``; constraint rows at material points that move with ``W``
  (:class:`~flexctrl.dynamics.fem.moving_frame.PointRows` per link, summed), their ``Phi_z``,
  ``h`` (Eq 47) and Newton tangents in closed form; a motion drive adds ``theta - theta(t)``,
  ``W - W(t)`` (minus their multipliers are the torque and force the motion needs);
* :class:`RPForces`: the prescribed inputs and the initial rigid state.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexctrl.dynamics.fem.moving_frame import FrameLink, RPMotion
from flexctrl.dynamics.fem.newmark_dae import DAEProblem, DAEResult, simulate
from flexctrl.errors import SpecError

Array = NDArray[np.float64]


@dataclass(frozen=True)
class RPForces:
    """Prescribed actuator inputs for full coupling (Eq 43) and the initial rigid state.

    ``torque(t)`` (N m) acts on joint 1 (angle ``theta``), ``force(t)`` (N) is the axial drive on
    the carriage at E (positive extends, increases ``W``).  ``theta0`` (rad), ``W0`` (m),
    ``thetad0`` (rad/s), ``Wd0`` (m/s): initial rigid state; the links start undeformed.
    """

    torque: Callable[[float], float]
    force: Callable[[float], float]
    theta0: float = 0.0
    W0: float = 0.3
    thetad0: float = 0.0
    Wd0: float = 0.0

    @classmethod
    def sine(
        cls, torque_amplitude: float, force_amplitude: float, T: float, **initial: float
    ) -> RPForces:
        """One sine period ``A sin(2 pi t / T)`` over ``[0, T]`` (s), zero after (N m and N)."""
        if not T > 0:
            raise SpecError(f"value {T!r} is not allowed; allowed: T > 0 s", key="T")

        def shape(a: float) -> Callable[[float], float]:
            return lambda t: a * math.sin(2 * math.pi * t / T) if 0.0 <= t <= T else 0.0

        return cls(torque=shape(torque_amplitude), force=shape(force_amplitude), **initial)

    @classmethod
    def from_samples(
        cls, t: ArrayLike, torque: ArrayLike, force: ArrayLike, **initial: float
    ) -> RPForces:
        """Inputs interpolated linearly between samples (s, N m, N), e.g. a motion's multipliers."""
        t, tau, F = (np.asarray(a, dtype=float).copy() for a in (t, torque, force))
        return cls(
            torque=lambda s: float(np.interp(s, t, tau)),
            force=lambda s: float(np.interp(s, t, F)),
            **initial,
        )


def shortening_matrices(link: FrameLink) -> tuple[Array, Array]:
    """``(Gs, Gx)``: the matrices of the shortening's integrals, ``s(x) = 1/2 int_0^x w'^2``.

    ``Gs = rho int (L - x) N'^T N'`` (``int rho s dx = 1/2 q.Gs q``) and
    ``Gx = rho int (L^2 - x^2)/2 N'^T N'`` (``int rho x s dx = 1/2 q.Gx q``).
    """
    L, rho = link.length, link.rho
    return rho * (L * link.G_c - link.G_1), rho * (0.5 * L * L * link.G_c - 0.5 * link.G_2)


def link_energies(
    link: FrameLink,
    q: Any,
    qd: Any,
    rE: Any,
    rEd: Any,
    thd: Any,
    g_ax: Any,
    g_perp: Any,
    shortening: bool,
) -> tuple[Any, Any]:
    """``(T, V)`` of one link (CasADi expressions; no payload), to second order in ``(q, qd)``.

    ``V`` holds strain and gravity (zero at ``q = 0``, ``r_E = 0``).

    Parameters
    ----------
    link : FrameLink
        The link's element matrices.
    q, qd : casadi.SX
        The link's ``2 (N + 1)`` nodal values and rates (m, rad; m/s, rad/s).
    rE, rEd : casadi.SX
        Radius of its root E and its rate, m and m/s.
    thd : casadi.SX
        Angular rate of the frame, rad/s.
    g_ax, g_perp : casadi.SX or float
        Gravity along and across the axis, m/s^2.
    shortening : bool
        Keep the axial shortening ``1/2 int w'^2`` in the kinematics.

    Returns
    -------
    T, V : casadi.SX
        Kinetic and potential energy, J.
    """
    import casadi as ca  # lazily: the numpy models never need CasADi

    DM = ca.DM
    rho, L = link.rho, link.length
    sh = 1.0 if shortening else 0.0
    Gs, Gx = (DM(G) for G in shortening_matrices(link))
    Ml, K, S0, S1 = DM(link.M_link), DM(link.K), DM(link.S0), DM(link.S1)

    def quad(A: Any, a: Any, b: Any) -> Any:
        return ca.dot(a, ca.mtimes(A, b))

    T = (
        0.5 * rho * L * rEd**2
        - sh * rEd * quad(Gs, qd, q)
        - rEd * thd * ca.dot(S0, q)
        + 0.5 * thd**2 * quad(Ml, q, q)
        + 0.5 * quad(Ml, qd, qd)
        + thd * ca.dot(qd, rE * S0 + S1)
        + 0.5 * thd**2 * rho * (L * rE**2 + L**2 * rE + L**3 / 3.0)
        - 0.5 * sh * thd**2 * (rE * quad(Gs, q, q) + quad(Gx, q, q))
    )
    V = (
        0.5 * quad(K, q, q)
        - g_ax * (rho * (L * rE + 0.5 * L * L) - 0.5 * sh * quad(Gs, q, q))
        - g_perp * ca.dot(S0, q)
    )
    return T, V


def payload_energies(
    link: FrameLink,
    mass: float,
    q: Any,
    qd: Any,
    rE: Any,
    rEd: Any,
    thd: Any,
    g_ax: Any,
    g_perp: Any,
    shortening: bool,
) -> tuple[Any, Any]:
    """``(T, V)`` of a point mass at the tip H of ``link``, expanded as :func:`link_energies`.

    Parameters
    ----------
    link : FrameLink
        The link carrying the mass.
    mass : float
        The point mass, kg.
    q, qd, rE, rEd, thd, g_ax, g_perp, shortening
        As for :func:`link_energies`.

    Returns
    -------
    T, V : casadi.SX
        Kinetic and potential energy, J.
    """
    import casadi as ca  # lazily: the numpy models never need CasADi

    sh = 1.0 if shortening else 0.0
    Gc = ca.DM(link.G_c)
    wL, wdL = q[link.tip], qd[link.tip]
    sL, sdL = 0.5 * sh * ca.dot(q, ca.mtimes(Gc, q)), sh * ca.dot(qd, ca.mtimes(Gc, q))
    r = rE + link.length
    T = (
        0.5
        * mass
        * (
            rEd**2
            - 2 * rEd * sdL
            - 2 * rEd * thd * wL
            + thd**2 * wL**2
            + wdL**2
            + 2 * thd * wdL * r
            + thd**2 * r**2
            - 2 * thd**2 * r * sL
        )
    )
    V = -g_ax * mass * (r - sL) - g_perp * mass * wL
    return T, V


@dataclass(frozen=True)
class FullCouplingResult:
    """What the fully coupled simulations return.

    ``t`` (s); ``theta`` (rad), ``thetad`` (rad/s), ``W`` (m), ``Wd`` (m/s): the nominal joint
    coordinates, now unknowns; ``torque`` (N m) and ``force`` (N): applied (force drive) or needed
    (motion drive, minus the joint multipliers); ``q``, ``qd`` nodal values and rates; ``lam`` the
    contact forces (N; N m for slope rows); ``tip_y`` transverse displacement of the tracked end in
    the link frame (m); contact violations (m, m/s); ``newton_iterations`` per step; ``wall_time``
    (s).
    """

    model: SlidingFullModel
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
    phi_violation: Array
    phidot_violation: Array
    newton_iterations: NDArray[np.int_]
    wall_time: float


class SlidingFullModel:
    """Base of the fully coupled models: ``z = (q, theta, W)``, the ``ne`` nodal values first.

    A subclass sets ``ne``, ``drive`` and calls :meth:`_build` with the symbols and ``T``, ``V``;
    it provides :meth:`contact_parts` (the constraint rows as parts per link) and :meth:`check_W`.
    """

    ne: int
    drive: RPForces | RPMotion

    def _build(self, z: Any, zd: Any, T: Any, V: Any) -> None:
        import casadi as ca  # lazily: the numpy models never need CasADi

        from flexctrl.dynamics.fem.newmark import DenseEvaluator  # imports CasADi

        self.ith, self.iW, self.nz = self.ne, self.ne + 1, self.ne + 2
        self.motion_driven = isinstance(self.drive, RPMotion)
        self.n_joint_rows = 2 if self.motion_driven else 0
        p = ca.gradient(T, zd)
        f = ca.gradient(T - V, z) - ca.mtimes(ca.jacobian(p, z), zd)
        self._fun = {
            "M": ca.Function("M", [z], [ca.jacobian(p, zd)]),
            "f": ca.Function("f", [z, zd], [f]),
            "f_z": ca.Function("f_z", [z, zd], [ca.jacobian(f, z)]),
            "f_zd": ca.Function("f_zd", [z, zd], [ca.jacobian(f, zd)]),
            "energy": ca.Function("energy", [z, zd], [T, V]),
            "momentum": ca.Function("p", [z, zd], [p]),
        }
        self._fast = {k: DenseEvaluator(self._fun[k]) for k in ("M", "f", "f_z", "f_zd")}
        self._parts_W: float | None = None

    # -- to provide --------------------------------------------------------------------------------
    def _parts(self, W: float) -> list[tuple[Array, Array]]:
        """``[(R, v), ...]`` per link part: ``R[d]`` (``d = 0..3``, rows x ``ne``), ``v = dx/dW``.

        To be provided by the subclass.
        """
        raise NotImplementedError

    def check_W(self, W: float, t: float) -> None:
        """Raise :class:`~flexctrl.errors.SimulationError` when ``W`` (m) leaves the stroke."""
        raise NotImplementedError

    # -- evaluation --------------------------------------------------------------------------------
    def contact_parts(self, W: float, t: float = math.nan) -> list[tuple[Array, Array]]:
        """The constraint rows at overhang ``W`` (cached per ``W``); see :meth:`_parts`."""
        self.check_W(W, t)
        if self._parts_W != W:
            self._parts_cache = self._parts(W)
            self._parts_W = W
        return self._parts_cache

    def _eval(self, name: str, *args: Array) -> Array:
        if name in self._fast:
            return self._fast[name](*args)[0]
        return np.asarray(self._fun[name](*args).full(), dtype=float)

    def mass(self, z: Array) -> Array:
        """Generalised mass ``M(z)`` (kg, kg m, kg m^2)."""
        return self._eval("M", z)

    def internal_force(self, z: Array, zd: Array) -> Array:
        """``dL/dz - (d^2 T / dzd dz) zd``: all but the actuator inputs and constraint forces."""
        return self._eval("f", z, zd).ravel()

    def energies(self, z: Array, zd: Array) -> tuple[float, float]:
        """Kinetic and potential energy ``(T, V)``, J."""
        T, V = self._fun["energy"](z, zd)
        return float(T), float(V)

    def momentum(self, z: Array, zd: Array) -> Array:
        """Momenta ``dT/dzd``; entry ``ith``: angular momentum about joint 1 (kg m^2/s)."""
        return self._eval("momentum", z, zd).ravel()

    def inputs(self, t: float) -> tuple[float, float]:
        """Applied ``(torque, force)`` (N m, N); zero under a motion drive (the multipliers)."""
        if isinstance(self.drive, RPMotion):
            return 0.0, 0.0
        return float(self.drive.torque(t)), float(self.drive.force(t))

    def contact_violations(self, z: Array, zd: Array, t: float = math.nan) -> tuple[Array, Array]:
        """``Phi`` and ``Phidot`` of the contact rows (m, m/s; rad, rad/s for slope rows)."""
        ne, W, Wd = self.ne, z[self.iW], zd[self.iW]
        parts = self.contact_parts(W, t)
        phi = sum(R[0] @ z[:ne] for R, _ in parts)
        phid = sum(R[0] @ zd[:ne] + Wd * v * (R[1] @ z[:ne]) for R, v in parts)
        return phi, phid

    def initial_state(self) -> tuple[Array, Array]:
        """Undeformed links at rest relative to the frame, rigid state from the drive."""
        z, zd = np.zeros(self.nz), np.zeros(self.nz)
        d = self.drive
        if isinstance(d, RPMotion):
            z[self.ith], z[self.iW] = float(d.theta(0.0)), float(d.W(0.0))
            zd[self.ith], zd[self.iW] = float(d.thetad(0.0)), float(d.Wd(0.0))
        else:
            z[self.ith], z[self.iW], zd[self.ith], zd[self.iW] = d.theta0, d.W0, d.thetad0, d.Wd0
        return z, zd

    def consistent_rates(self, z: Array, Wd: float) -> Array:
        """Smallest (mass-weighted) nodal rates with ``Phidot = 0``, sliding at ``Wd`` (m/s)."""
        ne = self.ne
        parts = self.contact_parts(z[self.iW])
        A = sum(R[0] for R, _ in parts)
        need = -Wd * sum(v * (R[1] @ z[:ne]) for R, v in parts)
        Minv_At = np.linalg.solve(self.mass(z)[:ne, :ne], A.T)
        return Minv_At @ np.linalg.solve(A @ Minv_At, need)

    def problem(self) -> DAEProblem:
        """``M(z) zdd + Phi_z^T lam = f(z, zd) + Q(t)`` with the contact (and joint) constraints."""
        ne, ith, iW, nz, nj = self.ne, self.ith, self.iW, self.nz, self.n_joint_rows
        d = self.drive if isinstance(self.drive, RPMotion) else None  # the joint rows' motion

        def force(z: Array, zd: Array, t: float) -> Array:
            out = self.internal_force(z, zd)
            tau, F = self.inputs(t)
            out[ith] += tau
            out[iW] += F
            return out

        def phi(z: Array, t: float) -> Array:
            contact = sum(R[0] @ z[:ne] for R, _ in self.contact_parts(z[iW], t))
            if d is None:
                return contact
            return np.r_[contact, z[ith] - float(d.theta(t)), z[iW] - float(d.W(t))]

        def phi_q(z: Array, t: float) -> Array:
            parts = self.contact_parts(z[iW], t)
            m = parts[0][0].shape[1]
            J = np.zeros((m + nj, nz))
            for R, v in parts:
                J[:m, :ne] += R[0]
                J[:m, iW] += v * (R[1] @ z[:ne])
            if nj:
                J[m, ith] = J[m + 1, iW] = 1.0
            return J

        def phi_t(z: Array, t: float) -> Array:
            m = self.contact_parts(z[iW], t)[0][0].shape[1]
            if d is None:
                return np.zeros(m)
            return np.r_[np.zeros(m), -float(d.thetad(t)), -float(d.Wd(t))]

        def h(z: Array, zd: Array, t: float) -> Array:
            q, qd, Wd = z[:ne], zd[:ne], zd[iW]
            contact = -sum(
                2 * Wd * v * (R[1] @ qd) + Wd**2 * v**2 * (R[2] @ q)
                for R, v in self.contact_parts(z[iW], t)
            )
            if d is None:
                return contact
            return np.r_[contact, float(d.thetadd(t)), float(d.Wdd(t))]

        def h_tangents(z: Array, zd: Array, t: float) -> tuple[Array, Array]:
            """``(dh/dz, dh/dzd)`` of the contact rows (a motion drive's joint rows have none)."""
            q, qd, Wd = z[:ne], zd[:ne], zd[iW]
            parts = self.contact_parts(z[iW], t)
            m = parts[0][0].shape[1]
            Jq, Jqd = np.zeros((m + nj, nz)), np.zeros((m + nj, nz))
            for R, v in parts:
                Jq[:m, :ne] -= (Wd**2 * v**2)[:, None] * R[2]
                Jq[:m, iW] -= 2 * Wd * v**2 * (R[2] @ qd) + Wd**2 * v**3 * (R[3] @ q)
                Jqd[:m, :ne] -= (2 * Wd * v)[:, None] * R[1]
                Jqd[:m, iW] -= 2 * v * (R[1] @ qd) + 2 * Wd * v**2 * (R[2] @ q)
            return Jq, Jqd

        return DAEProblem(
            n_q=nz,
            n_c=self.contact_parts(self.initial_state()[0][iW])[0][0].shape[1] + nj,
            mass=lambda z, t: self.mass(z),
            force=force,
            phi=phi,
            phi_q=phi_q,
            phi_t=phi_t,
            h=h,
            force_q=lambda z, zd, t: self._eval("f_z", z, zd),
            force_qd=lambda z, zd, t: self._eval("f_zd", z, zd),
            h_q=lambda z, zd, t: h_tangents(z, zd, t)[0],
            h_qd=lambda z, zd, t: h_tangents(z, zd, t)[1],
        )

    def run(
        self, dt: float, duration: float, initial_q: ArrayLike | None = None, **options: Any
    ) -> tuple[DAEResult, Array, Array, Array, Array]:
        """Newmark + Baumgarte from :meth:`initial_state`.

        ``initial_q`` replaces the nodal values (it must satisfy the contacts to 1e-9 m; the
        rates are made consistent); ``options`` go to
        :func:`~flexctrl.dynamics.fem.newmark_dae.simulate`.  Returns the result, the torque and
        force (applied, or needed by a motion drive: minus the joint multipliers) and the contact
        violations."""
        z0, zd0 = self.initial_state()
        if initial_q is not None:
            q0 = np.asarray(initial_q, dtype=float)
            if q0.shape != (self.ne,):
                raise SpecError(
                    f"initial_q has shape {q0.shape}; allowed: ({self.ne},)", key="initial_q"
                )
            z0[: self.ne] = q0
            off = np.abs(self.contact_violations(z0, np.zeros_like(zd0))[0]).max()
            if not off <= 1e-9:
                raise SpecError(
                    f"initial_q is {off:.3g} m off the contacts; allowed: <= 1e-9 m",
                    key="initial_q",
                )
            zd0[: self.ne] = self.consistent_rates(z0, zd0[self.iW])
        res = simulate(self.problem(), z0, zd0, float(duration), dt, **options)
        m = res.lam.shape[1] - self.n_joint_rows
        if self.motion_driven:
            torque, force = -res.lam[:, m], -res.lam[:, m + 1]
        else:
            applied = np.array([self.inputs(t) for t in res.t])
            torque, force = applied[:, 0], applied[:, 1]
        viol = [self.contact_violations(z, zd, t) for t, z, zd in zip(res.t, res.q, res.qd)]
        vp = np.array([np.abs(p).max() for p, _ in viol])
        vv = np.array([np.abs(v).max() for _, v in viol])
        return res, torque, force, vp, vv
