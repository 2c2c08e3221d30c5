"""Clamped-mass boundary values of each link from the arm and its configuration.

Subedi et al. (2021) Eqs 69-73 give, for the three-link arm, the tip mass
``m_D``, tip inertia ``J_D`` and first-moment coupling ``M_D`` that the
outboard links, hubs and payload exert on the tip of link ``i``.  Here they are
written for ``n`` links: the outboard bodies (hubs ``i+1..n``, links
``i+1..n``, payload) are placed in the *tip frame of link i* (origin on joint
``i+1``, x along link ``i``'s undeformed axis) by the joint angles
``q_{i+1}..q_n`` and

* ``m_D = sum m_b``;
* ``M_D = sum m_b x_b`` (first moment about the shearing axis: the projection of
  each centre of mass on link ``i``'s axis, as in Eq 69);
* ``J_D = sum (J_b + m_b r_b^2)`` with ``r_b`` the full distance of the body's
  centre from joint ``i+1`` (``boundary_inertia = "exact"``, the default), or
  with ``r_b`` replaced by the projection on the axis of link ``i+1`` as Eq 70
  writes ``d_l32 = l2 + l3/2 cos q3`` (``boundary_inertia = "paper"``).  The rigid
  moment of inertia about an axis needs the full squared distance; the paper's
  form reproduces its Figs 3 and 6-7.  Both agree when every outboard joint angle
  is 0 or 180 degrees, so Table 3 cannot tell them apart.

Conventions resolved here (recorded in ``models/subedi3link.toml`` too):

* the payload inertia ``J_p`` is carried only with a payload (``m_p > 0``);
* hub ``i+1`` sits on joint ``i+1`` (x = 0): it adds to ``m_D`` and, through its
  own inertia, to ``J_D`` but not to ``M_D``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexctrl.spec.arm import ArmSpec


@dataclass(frozen=True)
class BoundaryValues:
    """Tip-body values of one link (arrays broadcast over configurations).

    Attributes
    ----------
    m : numpy.ndarray
        Tip mass m_D (kg).
    J : numpy.ndarray
        Tip rotary inertia J_D about joint i+1 (kg m^2).
    M : numpy.ndarray
        First-moment coupling M_D (kg m).
    """

    m: np.ndarray
    J: np.ndarray
    M: np.ndarray


def boundary_values(
    arm: ArmSpec, q: np.ndarray, link: int, convention: str | None = None
) -> BoundaryValues:
    """Boundary values of ``link`` (0-based) at joint angles ``q``.

    Parameters
    ----------
    arm
        The arm (its payload is used).
    q
        Joint angles (rad), shape ``(n,)`` or ``(..., n)`` for many configurations.
    link
        Link index, 0-based.
    convention
        ``"exact"`` or ``"paper"``; defaults to ``arm.boundary_inertia``.

    Returns
    -------
    BoundaryValues
        Arrays of shape ``q.shape[:-1]``.
    """
    convention = convention or arm.boundary_inertia
    if convention not in ("exact", "paper"):
        raise ValueError(
            f"boundary_inertia {convention!r} is not allowed; allowed: 'exact', 'paper'"
        )
    q = np.asarray(q, dtype=float)
    shape = q.shape[:-1]
    zeros = np.zeros(shape)
    m_total, first, inertia = zeros.copy(), zeros.copy(), zeros.copy()

    # Bodies: (mass, own inertia, x, y, projection on link i+1 axis)
    theta = zeros.copy()
    px, py = zeros.copy(), zeros.copy()
    axis_angle = q[..., link + 1] if link + 1 < arm.n_links else zeros

    def add(mass: float, own: float, x: np.ndarray, y: np.ndarray) -> None:
        nonlocal m_total, first, inertia
        m_total = m_total + mass
        first = first + mass * x
        if convention == "exact":
            r2 = x**2 + y**2
        else:
            r2 = (x * np.cos(axis_angle) + y * np.sin(axis_angle)) ** 2
        inertia = inertia + own + mass * r2

    for k in range(link + 1, arm.n_links):
        add(arm.joints[k].hub_mass, arm.joints[k].hub_inertia, px, py)
        theta = theta + q[..., k]
        half = 0.5 * arm.links[k].length
        add(
            arm.links[k].mass,
            arm.links[k].inertia,
            px + half * np.cos(theta),
            py + half * np.sin(theta),
        )
        px = px + arm.links[k].length * np.cos(theta)
        py = py + arm.links[k].length * np.sin(theta)
    add(arm.payload.mass, arm.payload.effective_inertia, px, py)
    return BoundaryValues(m=m_total, J=inertia, M=first)


def scheduling_joints(arm: ArmSpec, link: int) -> tuple[int, ...]:
    """Joints (0-based) whose angles change the boundary values of ``link``.

    ``M_D`` of link i depends on ``q_{i+1}..q_n`` (0-based ``i+1..n-1``) and
    ``J_D`` on ``q_{i+2}..q_n``; a link with fewer than one outboard link has none.

    Parameters
    ----------
    arm : ArmSpec
        The arm described.
    link : int
        The link, 0-based.

    Returns
    -------
    tuple of int
        The joints, 0-based.
    """
    return tuple(range(link + 1, arm.n_links))
