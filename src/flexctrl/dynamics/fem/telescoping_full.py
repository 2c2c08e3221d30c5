"""Telescoping prismatic joint with full coupling (Pan et al. 1990, Fig 5 and Eq 43).

The pair of :mod:`flexctrl.dynamics.fem.telescoping` (an outer flexible tube clamped to the hub, an
inner flexible link sliding in it, contacts of Eqs 26-28), with the hub angle ``theta`` and the
overhang ``W`` among the unknowns: the inputs are the joint torque and the axial force on a
carriage at the inner root E (anchored at the hub, as in the partial model).

Coordinates ``z = (q1, q2, theta, W)``: the tube's nodal ``(w, w')`` without its clamped root node,
the inner link's, then the joint coordinates.  Each link's ``T`` and ``V`` are
:func:`~flexctrl.dynamics.fem.full_coupling.link_energies` in the frame turning with ``theta``: the
tube with its root at ``r0`` fixed, the inner link with E at ``r0 + L1 - L2 + W`` moving at ``W'``,
both with their axial shortening measured from their driven (tube: clamped) root; plus the payload
at the inner tip, the hub inertia and the carriage.  A contact row ``w1(x1_k) - w2(x2_k)`` (or of
the slopes) has a part on each link whose material point moves with ``W`` at ``dx1/dW = 1`` (a
bearing on the inner link) or ``dx2/dW = -1`` (a bearing on the tube); the constraint algebra is
:class:`~flexctrl.dynamics.fem.full_coupling.SlidingFullModel`'s.

With ``theta(t)``, ``W(t)`` imposed (an :class:`~flexctrl.dynamics.fem.moving_frame.RPMotion` drive)
the nodal rows are the partial model's (Pan's ``K_g`` of each link included; a test compares).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from flexctrl.dynamics.fem.full_coupling import (
    FullCouplingResult,
    RPForces,
    SlidingFullModel,
    link_energies,
    payload_energies,
)
from flexctrl.dynamics.fem.moving_frame import FrameLink, PointRows, RPMotion, check_elements
from flexctrl.errors import SimulationError, SpecError
from flexctrl.spec.fem_models import TelescopingSpec

Array = NDArray[np.float64]


class TelescopingFullModel(SlidingFullModel):
    """The telescoping pair with ``theta`` and ``W`` unknown.

    ``drive`` is an :class:`RPForces` or an :class:`RPMotion`.
    """

    def __init__(
        self,
        spec: TelescopingSpec,
        drive: RPForces | RPMotion,
        n_outer: int = 8,
        n_inner: int = 8,
        *,
        axial_shortening: bool = True,
    ):
        import casadi as ca  # lazily: the numpy models never need CasADi

        check_elements(n_outer, "n_outer")
        check_elements(n_inner, "n_inner")
        if not isinstance(drive, (RPForces, RPMotion)):
            raise SpecError(
                f"value {drive!r} is not allowed; allowed: an RPForces or an RPMotion", key="drive"
            )
        self.spec, self.drive, self.n1, self.n2 = spec, drive, int(n_outer), int(n_inner)
        self.axial_shortening = bool(axial_shortening)
        o, i = spec.outer, spec.inner
        self.ds = o.length - i.length  # s = ds + W
        W0 = float(drive.W(0.0)) if isinstance(drive, RPMotion) else float(drive.W0)
        spec.check_stroke([self.ds + W0], key="W0")
        self.outer = FrameLink(self.n1, o.length, o.mass_per_length, o.EI)
        self.inner = FrameLink(self.n2, i.length, i.mass_per_length, i.EI)
        self.n_q1 = self.outer.ndof - 2
        self.ne = self.n_q1 + self.inner.ndof
        self.tip, self.outer_tip = self.n_q1 + self.inner.tip, self.n_q1 - 2
        on_inner = [c.on == "inner" for c in spec.contacts]
        orders, off1, v1, off2, v2 = [], [], [], [], []
        for c, inner in zip(spec.contacts, on_inner):
            for order in (0, 1) if c.slope else (0,):
                orders.append(order)
                off1.append(c.at + self.ds if inner else c.at)
                v1.append(1.0 if inner else 0.0)
                off2.append(c.at if inner else c.at - self.ds)
                v2.append(0.0 if inner else -1.0)
        self.rows_outer = PointRows(tuple(orders), tuple(off1), tuple(v1))
        self.rows_inner = PointRows(tuple(orders), tuple(off2), tuple(v2))

        z, zd = ca.SX.sym("z", self.ne + 2), ca.SX.sym("zd", self.ne + 2)
        th, W, thd, Wd = z[self.ne], z[self.ne + 1], zd[self.ne], zd[self.ne + 1]
        q1, qd1 = ca.vertcat(0, 0, z[: self.n_q1]), ca.vertcat(0, 0, zd[: self.n_q1])
        q2, qd2 = z[self.n_q1 : self.ne], zd[self.n_q1 : self.ne]
        gx, gy = spec.gravity
        g_ax, g_perp = gx * ca.cos(th) + gy * ca.sin(th), -gx * ca.sin(th) + gy * ca.cos(th)
        r0, rE = spec.hub_radius, spec.hub_radius + self.ds + W
        sh = self.axial_shortening
        T1, V1 = link_energies(self.outer, q1, qd1, r0, 0.0, thd, g_ax, g_perp, sh)
        T2, V2 = link_energies(self.inner, q2, qd2, rE, Wd, thd, g_ax, g_perp, sh)
        Tp, Vp = payload_energies(
            self.inner, spec.payload_mass, q2, qd2, rE, Wd, thd, g_ax, g_perp, sh
        )
        m_c = spec.carriage_mass
        T = T1 + T2 + Tp + 0.5 * spec.hub_inertia * thd**2 + 0.5 * m_c * (Wd**2 + rE**2 * thd**2)
        V = V1 + V2 + Vp - g_ax * m_c * rE
        self._build(z, zd, T, V)

    def check_W(self, W: float, t: float) -> None:
        """Raise :class:`SimulationError` when the overhang ``W`` (m) leaves the stroke at ``t``."""
        try:
            self.spec.check_stroke([self.ds + W], key="W")
        except SpecError as exc:
            raise SimulationError(
                f"at t = {t:.6g} s the overhang W = {W:.6g} m took a contact off a link "
                f"(full coupling; reduce the axial force or the duration): {exc}"
            ) from exc

    def _parts(self, W: float) -> list[tuple[Array, Array]]:
        o, i = self.spec.outer, self.spec.inner
        R1 = np.zeros((4, self.rows_outer.count, self.ne))
        R2 = np.zeros_like(R1)
        R1[:, :, : self.n_q1] = self.rows_outer.at(W, self.n1, o.length)[:, :, 2:]
        R2[:, :, self.n_q1 :] = -self.rows_inner.at(W, self.n2, i.length)
        return [(R1, np.asarray(self.rows_outer.rates)), (R2, np.asarray(self.rows_inner.rates))]


@dataclass(frozen=True)
class TelescopingFullResult(FullCouplingResult):
    """Response of :func:`simulate_telescoping_full`: the fields of
    :class:`~flexctrl.dynamics.fem.full_coupling.FullCouplingResult` (``tip_y`` of the inner link)
    and ``outer_tip_y``, the transverse displacement of the tube mouth (m)."""

    outer_tip_y: Array


def simulate_telescoping_full(
    spec: TelescopingSpec,
    drive: RPForces | RPMotion,
    n_outer: int = 8,
    n_inner: int = 8,
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
) -> TelescopingFullResult:
    """Simulate the fully coupled telescoping pair by Newmark + Baumgarte, from undeformed links.

    Parameters as :func:`flexctrl.dynamics.fem.rp_arm_full.simulate_rp_arm_full`; ``n_outer``,
    ``n_inner`` the elements per link.

    Raises
    ------
    SimulationError
        A contact left a link or a constraint violation diverged.
    SolverError
        Newton failed to converge.
    """
    if tracked_end not in ("E", "H"):
        raise SpecError(
            f"value {tracked_end!r} is not allowed; allowed: 'E', 'H'", key="tracked_end"
        )
    model = TelescopingFullModel(spec, drive, n_outer, n_inner, axial_shortening=axial_shortening)
    res, torque, force, vp, vv = model.run(
        dt,
        duration,
        None,
        gamma=gamma,
        beta=beta,
        alpha=alpha,
        delta=delta,
        max_violation=max_violation,
        newton_tol=newton_tol,
        max_iterations=max_iterations,
    )
    ne, ith, iW = model.ne, model.ith, model.iW
    dof = model.n_q1 if tracked_end == "E" else model.tip
    return TelescopingFullResult(
        model=model,
        dt=res.dt,
        t=res.t,
        theta=res.q[:, ith],
        thetad=res.qd[:, ith],
        W=res.q[:, iW],
        Wd=res.qd[:, iW],
        torque=torque,
        force=force,
        tip_y=res.q[:, dof],
        outer_tip_y=res.q[:, model.outer_tip],
        q=res.q[:, :ne],
        qd=res.qd[:, :ne],
        lam=res.lam[:, : model.rows_outer.count],
        phi_violation=vp,
        phidot_violation=vv,
        newton_iterations=res.newton_iterations,
        wall_time=res.wall_time,
    )
