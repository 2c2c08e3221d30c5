"""A small analytic :class:`~flexctrl.dynamics.model.Model` for the tests.

Two rigid links with point masses at their ends (a double pendulum, joints
``q1``, ``q2``) carry a third mass that slides along link 2 on a spring of
stiffness ``k``: its radial displacement ``qf21`` from the rest position ``r0``
is the one elastic coordinate.  With the joints locked the spring-mass
oscillates at ``omega = sqrt(k / m3)``, which is the model's ``omega_max``;
raising ``k`` makes the problem as stiff as wanted.  The equations come from the
Lagrangian, derived symbolically with CasADi, so the model presents every
function of the :class:`Model` interface and conserves energy exactly.

Examples
--------
>>> from support_models import spring_pendulum
>>> model = spring_pendulum(k=1.0e4)
>>> model.coordinate_names
('q1', 'q2', 'qf21')
>>> round(model.omega_max, 3)
100.0
"""

from __future__ import annotations

import math

import casadi as ca

from flexctrl.dynamics.model import Model
from flexctrl.spec.fidelity import Fidelity


def spring_pendulum(
    *,
    l1: float = 1.0,
    l2: float = 0.8,
    m1: float = 1.0,
    m2: float = 0.5,
    m3: float = 1.0,
    r0: float = 0.5,
    k: float = 1.0e4,
    zeta: float = 0.0,
    friction: float = 0.0,
    gravity: tuple[float, float] = (0.0, -9.81),
) -> Model:
    """Build the double pendulum with a spring-mass coordinate (SI units).

    Parameters
    ----------
    l1, l2
        Link lengths (m); point masses ``m1``, ``m2`` (kg) sit at the link ends.
    m3, r0, k
        Sliding mass (kg), its rest distance from joint 2 along link 2 (m) and the
        spring stiffness (N/m).
    zeta
        Damping ratio of the spring-mass (locked joints).
    friction
        Viscous joint friction (N m s/rad), both joints.
    gravity
        Gravity vector in the world frame (m/s^2).
    """
    q = ca.SX.sym("q", 3)
    qd = ca.SX.sym("qd", 3)
    u = ca.SX.sym("u", 2)
    gvec = ca.DM(list(gravity))
    e1 = ca.vertcat(ca.cos(q[0]), ca.sin(q[0]))
    a2 = q[0] + q[1]
    e2 = ca.vertcat(ca.cos(a2), ca.sin(a2))
    p1 = l1 * e1
    p2 = p1 + l2 * e2
    p3 = p1 + (r0 + q[2]) * e2
    points = [(m1, p1), (m2, p2), (m3, p3)]
    kin = 0
    grav = 0
    for mass, p in points:
        v = ca.jtimes(p, q, qd)
        kin += 0.5 * mass * ca.dot(v, v)
        grav -= mass * ca.dot(gvec, p)
    elastic = 0.5 * k * q[2] ** 2
    mass_matrix = ca.hessian(kin, qd)[0]
    coriolis = ca.jtimes(ca.mtimes(mass_matrix, qd), q, qd) - ca.gradient(kin, q)
    gravity_vec = ca.gradient(grav, q)
    stiffness = ca.DM.zeros(3, 3)
    stiffness[2, 2] = k
    damping = ca.DM.zeros(3, 3)
    damping[0, 0] = damping[1, 1] = friction
    damping[2, 2] = 2.0 * zeta * math.sqrt(k * m3)
    tau = ca.vertcat(u, 0)
    rhs = tau - coriolis - gravity_vec - ca.mtimes(stiffness, q) - ca.mtimes(damping, qd)
    qdd = ca.solve(mass_matrix, rhs)
    x = ca.vertcat(q, qd)
    tip_p = p2
    tip_v = ca.jtimes(p2, q, qd)
    hubs = ca.horzcat(ca.DM.zeros(2, 1), p1, p2)
    functions = {
        "M": ca.Function("M", [q], [mass_matrix], ["q"], ["M"]),
        "c": ca.Function("c", [q, qd], [coriolis], ["q", "qd"], ["c"]),
        "g": ca.Function("g", [q], [gravity_vec], ["q"], ["g"]),
        "K": ca.Function("K", [], [stiffness], [], ["K"]),
        "D": ca.Function("D", [], [damping], [], ["D"]),
        "f": ca.Function("f", [x, u], [ca.vertcat(qd, qdd)], ["x", "u"], ["xdot"]),
        "energies": ca.Function(
            "energies", [q, qd], [kin, elastic, grav], ["q", "qd"], ["E_kin", "E_el", "E_grav"]
        ),
        "tip": ca.Function("tip", [q, qd], [tip_p, tip_v], ["q", "qd"], ["p", "v"]),
        "hubs": ca.Function("hubs", [q], [hubs], ["q"], ["p"]),
        "deflection": ca.Function(
            "deflection", [q], [ca.vertcat(0, q[2]), ca.DM.zeros(2, 1)], ["q"], ["w", "dw"]
        ),
    }
    return Model(
        name="spring_pendulum",
        fidelity=Fidelity("amm", 1),
        n_joints=2,
        coordinate_names=("q1", "q2", "qf21"),
        functions=functions,
        omega_max=math.sqrt(k / m3),
        info={"k": k, "m3": m3, "zeta": zeta},
    )
