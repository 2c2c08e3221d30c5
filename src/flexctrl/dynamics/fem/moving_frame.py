"""Pieces shared by the finite-element models with moving supports (Pan, Scott & Ulsoy 1990).

* :class:`FrameLink`: one uniform link of Hermite elements measured in a frame that turns with
  ``theta`` and slides along its axis, with the time-varying terms of the partially coupled
  equations (Eq 42: ``-theta'^2 M`` softening, rigid-motion loads, ``K_g`` of Eqs 16-18);
* :class:`RPMotion`: the smooth rest-to-rest profile of Eq 57 for the overhang ``W(t)`` and the
  housing angle ``theta(t)``;
* :func:`point_rows`: the rows giving ``w`` and its derivatives at arbitrary material points,
  which move from element to element as the supports slide;
* :class:`PointRows` and :func:`prismatic_rows`: the constraint rows of a prismatic joint, at
  material points that move with the overhang ``W`` (two supports, or Pan's Fig 4 clamp plus
  mouth bearing);
* :func:`check_elements` and :data:`ENDS`, the checks the models share.

Used by :mod:`flexctrl.dynamics.fem.rp_arm` (partial coupling),
:mod:`flexctrl.dynamics.fem.rp_arm_full` (full coupling) and
:mod:`flexctrl.dynamics.fem.telescoping`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexctrl.beam.elements import (
    assemble_beam,
    assemble_geometric_stiffness,
    hermite_shape,
    locate,
)
from flexctrl.errors import SpecError

Array = NDArray[np.float64]
#: A number, a numpy array or a CasADi expression: the rigid motion and the terms built from it
#: are numeric for the Newmark models and symbolic for IDAS (:mod:`.idas_dae`), one code for both.
NumOrSym = Any
#: The ends of a sliding link: E (material coordinate 0) and H (the tip).
ENDS = ("E", "H")


def check_elements(n_elements: object, key: str = "n_elements") -> None:
    """Raise :class:`SpecError` unless ``n_elements`` is an integer from 1 to 256.

    Parameters
    ----------
    n_elements : object
        The element count asked for.
    key : str
        The key the error names.
    """
    if (
        isinstance(n_elements, bool)
        or not isinstance(n_elements, (int, np.integer))
        or not 1 <= n_elements <= 256
    ):
        raise SpecError(
            f"value {n_elements!r} is not allowed; allowed: an integer from 1 to 256", key=key
        )


def point_rows(xs: ArrayLike, n_elements: int, length: float, max_derivative: int = 2) -> Array:
    """Rows ``R[d, k]`` with ``w^(d)(x_k) = R[d, k] @ q``, ``d = 0..max_derivative``.

    On a uniform mesh of ``n_elements`` Hermite elements over ``length`` (m); each row holds the
    shape functions of the element containing ``x_k`` (an interior node belongs to the element
    on its right).

    Parameters
    ----------
    xs : array_like
        Material points, m.
    n_elements : int
        Elements of the mesh.
    length : float
        Link length, m.
    max_derivative : int
        Highest derivative along the link.

    Returns
    -------
    ndarray
        ``(max_derivative + 1, len(xs), 2 (n_elements + 1))``.
    """
    xs = np.atleast_1d(np.asarray(xs, dtype=float))
    le = length / n_elements
    R = np.zeros((max_derivative + 1, xs.size, 2 * (n_elements + 1)))
    located = [locate(float(x), n_elements, length) for x in xs]
    zetas = np.array([z for _, z in located])
    for d in range(max_derivative + 1):
        H = hermite_shape(zetas, le, d)
        for k, (j, _) in enumerate(located):
            R[d, k, 2 * j : 2 * j + 4] = H[k]
    return R


@dataclass(frozen=True)
class PointRows:
    """Constraint rows ``w^(o_k)(x_k) = 0`` at material points ``x_k = c_k + v_k W`` of one link.

    ``orders`` ``o_k`` (0: displacement, 1: slope), ``offsets`` ``c_k`` (m) and ``rates``
    ``v_k = dx_k/dW`` (0 for a point fixed on the link, -1 for a support fixed in the housing).
    """

    orders: tuple[int, ...]
    offsets: tuple[float, ...]
    rates: tuple[float, ...]

    @property
    def count(self) -> int:
        """Number of rows."""
        return len(self.orders)

    def points(self, W: float) -> Array:
        """Material coordinates ``x_k`` (m) at overhang ``W`` (m)."""
        return np.asarray(self.offsets) + np.asarray(self.rates) * W

    def at(self, W: float, n_elements: int, length: float) -> Array:
        """``R[d, k]`` (``d = 0..3``): the ``d``-th derivative along the link of row ``k``.

        ``w^(o_k + d)(x_k) = R[d, k] @ q`` (zero beyond the cubic's third derivative).
        """
        P = point_rows(self.points(W), n_elements, length, 3)
        R = np.zeros((4, self.count, P.shape[2]))
        for d in range(4):
            for k, o in enumerate(self.orders):
                if o + d <= 3:
                    R[d, k] = P[o + d, k]
        return R


def prismatic_rows(joint: str, length: float, D: float) -> PointRows:
    """The rows of an R-P arm's prismatic joint: a link of ``length`` (m), supports ``D`` (m) apart.

    ``"supports"``: ``w = 0`` at the two supports, material points ``L - D - W`` and ``L - W``
    (Eqs 24-25 at each).  ``"clamped"`` (Pan's Fig 4): ``w(0) = w'(0) = 0`` at E in the carriage
    (Eqs 22-23, fixed on the link) and ``w = 0`` at the mouth bearing D', material point ``L - W``
    (Eq 24).

    Parameters
    ----------
    joint : {"supports", "clamped"}
        The joint's kind.
    length : float
        Link length, m.
    D : float
        Distance of the supports, m.

    Returns
    -------
    PointRows
        The rows' derivative orders, material offsets (m) and their rates ``dx/dW``.
    """
    if joint == "supports":
        return PointRows((0, 0), (length - D, length), (-1.0, -1.0))
    if joint == "clamped":
        return PointRows((0, 1, 0), (0.0, 0.0, length), (0.0, 0.0, -1.0))
    raise SpecError(f"value {joint!r} is not allowed; allowed: 'supports', 'clamped'", key="joint")


def is_symbolic(value: object) -> bool:
    """True for a CasADi expression (``SX``/``MX``), e.g. a symbolic time."""
    return type(value).__module__.startswith("casadi")


def _profile(t: NumOrSym, T: float, derivative: int) -> NumOrSym:
    """Eq 57's unit rest-to-rest profile ``s(t) = t/T - sin(2 pi t/T)/(2 pi)``, held outside [0, T].

    ``t`` may be a CasADi expression (a symbolic time; :mod:`flexctrl.dynamics.fem.idas_dae`)."""
    sin: Callable[[Any], Any]
    cos: Callable[[Any], Any]
    clip: Callable[[Any], Any]
    where: Callable[..., Any]
    if is_symbolic(t):
        import casadi as ca  # lazily: the numpy models never need CasADi

        sin, cos, clip = ca.sin, ca.cos, lambda x: ca.fmin(ca.fmax(x, 0.0), T)
        where = ca.if_else
        inside = ca.logic_and(t >= 0, t <= T)
    else:
        t = np.asarray(t, dtype=float)
        sin, cos, clip, where = np.sin, np.cos, lambda x: np.clip(x, 0.0, T), np.where
        inside = (t >= 0) & (t <= T)
    w = 2 * np.pi / T
    if derivative == 0:
        tc = clip(t)
        return tc / T - sin(w * tc) / (2 * np.pi)
    if derivative == 1:
        return where(inside, (1.0 - cos(w * t)) / T, 0.0)
    return where(inside, w * sin(w * t) / T, 0.0)


@dataclass(frozen=True)
class RPMotion:
    """Prescribed motion ``W(t) = C1 - C2 s(t)`` (m), ``theta(t) = theta0 + dtheta s(t)`` (rad).

    ``s`` is Eq 57's profile over ``T`` seconds; ``C2 < 0`` extends the link.
    """

    C1: float
    C2: float
    T: float
    theta0: float = 0.0
    dtheta: float = 0.0

    def W(self, t: NumOrSym) -> NumOrSym:
        """Overhang beyond the outer support, m."""
        return self.C1 - self.C2 * _profile(t, self.T, 0)

    def Wd(self, t: NumOrSym) -> NumOrSym:
        """Rate of the overhang, m/s."""
        return -self.C2 * _profile(t, self.T, 1)

    def Wdd(self, t: NumOrSym) -> NumOrSym:
        """Acceleration of the overhang, m/s^2."""
        return -self.C2 * _profile(t, self.T, 2)

    def theta(self, t: NumOrSym) -> NumOrSym:
        """Housing angle, rad."""
        return self.theta0 + self.dtheta * _profile(t, self.T, 0)

    def thetad(self, t: NumOrSym) -> NumOrSym:
        """Housing rate, rad/s."""
        return self.dtheta * _profile(t, self.T, 1)

    def thetadd(self, t: NumOrSym) -> NumOrSym:
        """Housing acceleration, rad/s^2."""
        return self.dtheta * _profile(t, self.T, 2)


class FrameLink:
    """One uniform link of Hermite elements in a frame that turns with ``theta`` and whose origin
    (the link's material point ``x = 0``) sits on the frame's axis at radius ``r_E(t)``.

    Holds the constant matrices (``M`` with the payload on the tip ``w``, ``K``, ``S0 = int rho N``,
    ``S1 = int rho x N`` and the geometric-stiffness pieces ``G_c, G_1, G_2`` for ``F = 1, x, x^2``)
    and forms the time-varying terms of the partially coupled equations (Eq 42; derivation in
    :mod:`flexctrl.dynamics.fem.rp_arm`)::

        M qdd + (K + K_g - theta'^2 M) q = f,
        f = -int rho N^T (theta'' (r_E + x) + 2 theta' r_E' - g_perp) (+ payload at x = L).

    Shared by :class:`~flexctrl.dynamics.fem.rp_arm.RPArmModel` and
    :mod:`flexctrl.dynamics.fem.telescoping`.
    """

    def __init__(
        self,
        n_elements: int,
        length: float,
        mass_per_length: float,
        EI: float,
        payload_mass: float = 0.0,
    ):
        self.n, self.length, self.rho, self.payload_mass = (
            int(n_elements),
            float(length),
            float(mass_per_length),
            float(payload_mass),
        )
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

    def force_coefficients(
        self, r: Mapping[str, NumOrSym], driven_end: str
    ) -> tuple[NumOrSym, NumOrSym, NumOrSym]:
        """``(c0, c1, c2)`` of the rigid-motion axial force ``F = c0 + c1 x + c2 x^2`` (N).

        Tension is positive.  ``r`` holds ``rE, rEd, rEdd`` (m, m/s, m/s^2), ``thd`` (rad/s),
        ``g_ax`` (m/s^2).  Driven at E (the reaction of the whole link and payload enters at
        ``x = 0``): ``F(x) = -int_x^L rho a~ - m_t a~(L)``; driven at H: ``F(x) = int_0^x rho a~``;
        ``a~ = r_E'' - theta'^2 (r_E + x) - g_ax``.
        """
        rho, L, m_t = self.rho, self.length, self.payload_mass
        # a~(x) = b0 - w2 x  with b0 = rE'' - th'^2 rE - g_ax, w2 = th'^2
        b0 = r["rEdd"] - r["thd"] ** 2 * r["rE"] - r["g_ax"]
        w2 = r["thd"] ** 2
        if driven_end == "E":  # F = -int_x^L rho a~ - m_t a~(L)
            c0 = -rho * (b0 * L - 0.5 * w2 * L * L) - m_t * (b0 - w2 * L)
            return c0, rho * b0, -0.5 * rho * w2
        return 0.0, rho * b0, -0.5 * rho * w2  # F = int_0^x rho a~

    def terms(
        self, r: Mapping[str, NumOrSym], driven_end: str, axial_shortening: bool
    ) -> tuple[NumOrSym, NumOrSym]:
        """``(K + K_g - theta'^2 M, f)`` for the rigid state ``r`` (see :meth:`force_coefficients`;
        also ``thdd`` in rad/s^2 and ``g_perp`` in m/s^2).  Numbers give numpy arrays; CasADi
        expressions (a symbolic rigid motion) give CasADi matrices."""
        mats: tuple[Any, ...] = (
            self.K,
            self.M,
            self.G_c,
            self.G_1,
            self.G_2,
            self.S0,
            self.S1,
            np.eye(self.ndof)[self.tip],
        )
        if not all(isinstance(v, (int, float, np.floating, np.integer)) for v in r.values()):
            import casadi as ca  # lazily: the numpy models never need CasADi

            mats = tuple(ca.DM(m) for m in mats)
        K, M, G_c, G_1, G_2, S0, S1, e_tip = mats
        Kt = K - r["thd"] ** 2 * M
        if axial_shortening:
            c0, c1, c2 = self.force_coefficients(r, driven_end)
            Kt = Kt + c0 * G_c + c1 * G_1 + c2 * G_2
        a0 = r["thdd"] * r["rE"] + 2.0 * r["thd"] * r["rEd"]  # a_perp(x) = a0 + thdd x
        f = -(a0 - r["g_perp"]) * S0 - r["thdd"] * S1
        if self.payload_mass:
            f = f - self.payload_mass * (a0 + r["thdd"] * self.length - r["g_perp"]) * e_tip
        return Kt, f
