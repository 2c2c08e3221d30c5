"""Operating points, sensors, linearisation and discretisation of a
:class:`~flexctrl.dynamics.model.Model`.

* :func:`equilibrium`: the joints hold the arm against gravity at given joint
  angles; the elastic coordinates take their static deflection
  (``g(q) + K q = B tau``: Newton on the elastic rows, torques from the joint rows).
  :func:`operating_point` wraps any given state and input.
* :class:`Sensors`: what a real arm measures (joint encoders, joint rates, strain
  gauges at the link roots, tip position, tip acceleration, tip deflections, or
  the full state), each with a noise standard deviation; one CasADi Function
  ``y(x, u)``.
* :func:`linearize`: exact Jacobians (CasADi AD) at an operating point, returned
  as a ``control.StateSpace`` with named states ``q1.., qf11.., dq1.., dqf11..``,
  inputs ``tau1..`` and the sensor outputs; :func:`discretize` by zero-order hold.
* :func:`modal_summary` (frequencies and damping of a linear system) and
  :func:`locked_frequencies` (joints clamped: ``K_ff`` against ``M_ff``).

All quantities are SI; angles in radians.  Linear systems are in deviation
variables about the operating point: ``dx = x - op.x``, ``du = u - op.u``,
``dy = y - sensors(op.x, op.u)``.

Examples
--------
>>> import numpy as np
>>> from flexctrl.sim.toymodel import spring_pendulum
>>> model = spring_pendulum(k=1.0e4)
>>> op = equilibrium(model, [0.3, -0.2])
>>> sys = linearize(model, op, outputs=("joints",))
>>> sys.state_labels[:4], sys.input_labels, sys.output_labels
(['q1', 'q2', 'qf21', 'dq1'], ['tau1', 'tau2'], ['q1', 'q2'])
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import casadi as ca
import control
import numpy as np

from flexctrl.dynamics.amm import locked_spectrum
from flexctrl.dynamics.jacobians import jacobian_function
from flexctrl.dynamics.model import derived
from flexctrl.errors import SolverError, SpecError
from flexctrl.spec.sensors import DEFAULT_NOISE, SENSOR_KINDS
from flexctrl.spec.units import warn_if_degrees


# --------------------------------------------------------------------------------------
# model helpers
# --------------------------------------------------------------------------------------
def state_names(model) -> tuple[str, ...]:
    """``q1.., qf11.., dq1.., dqf11..``: coordinates, then their rates prefixed by ``d``."""
    names = tuple(model.coordinate_names)
    return names + tuple("d" + n for n in names)


def input_names(model) -> tuple[str, ...]:
    """``tau1..taun``."""
    return tuple(f"tau{i + 1}" for i in range(model.n_u))


def stiffness_matrix(model, q) -> np.ndarray | ca.SX | ca.MX:
    """``K`` of the model (constant, or at ``q`` for configuration-scheduled modes).

    ``q`` may be numeric (returns ndarray) or symbolic (returns the CasADi expression).
    """
    fun = model.functions.get("K")
    symbolic = isinstance(q, (ca.SX, ca.MX))
    if fun is None:
        return ca.DM.zeros(model.n_q, model.n_q) if symbolic else np.zeros((model.n_q, model.n_q))
    value = fun(q) if fun.n_in() == 1 else fun()["K"]
    return value if symbolic else np.array(value, dtype=float)


def torque_limits(model, default: float = math.inf) -> np.ndarray:
    """Joint torque limits (N m) from the arm description, or ``info["torque_limits"]``, else ``default``."""
    spec = getattr(model, "spec", None)
    joints = getattr(spec, "joints", None)
    if joints is not None and len(joints) == model.n_u:
        return np.array([float(j.torque_limit) for j in joints])
    info = getattr(model, "info", {}) or {}
    if "torque_limits" in info:
        return np.broadcast_to(np.asarray(info["torque_limits"], dtype=float), (model.n_u,)).copy()
    return np.full(model.n_u, float(default))


def flexible_index(model) -> np.ndarray:
    """Indices of the elastic coordinates in ``q``."""
    return np.arange(model.n_u, model.n_q)


# --------------------------------------------------------------------------------------
# operating points
# --------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class OperatingPoint:
    """A state and input about which a model is linearised.

    Attributes
    ----------
    x : ndarray (2N,)
        State ``(q, qd)``.
    u : ndarray (n,)
        Joint torques, N m.
    kind : {"equilibrium", "given"}
        How it was made.
    residual : float
        ``max |f(x, u)|`` (0 for an exact equilibrium).
    iterations : int
        Newton iterations used (0 for a given point).
    """

    x: np.ndarray
    u: np.ndarray
    kind: Literal["equilibrium", "given"] = "given"
    residual: float = float("nan")
    iterations: int = 0

    def __post_init__(self) -> None:
        for name in ("x", "u"):
            value = np.array(getattr(self, name), dtype=float).ravel()
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n_q(self) -> int:
        """Number of coordinates N."""
        return self.x.size // 2

    @property
    def q(self) -> np.ndarray:
        """Coordinates (rad, m)."""
        return self.x[: self.n_q]

    @property
    def qd(self) -> np.ndarray:
        """Rates."""
        return self.x[self.n_q :]

    @property
    def joints(self) -> np.ndarray:
        """Joint angles (rad)."""
        return self.q[: self.u.size]


def _xdot(model, x, u) -> np.ndarray:
    return np.array(model.functions["f"](x, u), dtype=float).ravel()


def operating_point(model, x, u) -> OperatingPoint:
    """Wrap a given state ``x`` (2N,) and input ``u`` (n,) as an :class:`OperatingPoint`."""
    x = np.asarray(x, dtype=float).ravel()
    u = np.asarray(u, dtype=float).ravel()
    if x.size != model.n_x:
        raise SpecError(
            f"state has {x.size} entries; expected {model.n_x} (q then qd: {', '.join(state_names(model))})",
            key="x",
        )
    if u.size != model.n_u:
        raise SpecError(f"input has {u.size} entries; expected {model.n_u} joint torques", key="u")
    return OperatingPoint(x, u, "given", float(np.max(np.abs(_xdot(model, x, u)), initial=0.0)), 0)


def _static_functions(model) -> ca.Function:
    """``(qr, qf) -> (r_f, J_f, tau)``: elastic residual, its Jacobian in qf, joint torques."""
    n, N = model.n_u, model.n_q
    qr = ca.SX.sym("qr", n)
    qf = ca.SX.sym("qf", N - n)
    q = ca.vertcat(qr, qf)
    g = model.functions["g"](q)
    K = stiffness_matrix(model, q)
    static = g + ca.mtimes(K, q)  # = B tau at rest
    r_f = static[n:]
    return ca.Function(
        "static", [qr, qf], [r_f, ca.jacobian(r_f, qf), static[:n]], ["qr", "qf"], ["r", "J", "tau"]
    )


def equilibrium(
    model,
    q_joints: Sequence[float],
    *,
    tol: float = 1e-12,
    max_iter: int = 50,
    q_flex0: Sequence[float] | None = None,
) -> OperatingPoint:
    """The static equilibrium with the joints at ``q_joints`` (rad), held by joint torques.

    Solves ``[g(q) + K q]_f = 0`` for the elastic coordinates by Newton's method
    (Jacobian by CasADi AD, converged when the step is below ``tol`` relative to
    ``1 + |q_f|``) and takes the joint torques from the joint rows,
    ``tau = [g(q) + K q]_r``.  Velocities are zero.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
    q_joints : sequence of float
        Joint angles, rad (one per joint).
    tol : float
        Newton's relative step tolerance.
    max_iter : int
        Newton iterations at most.
    q_flex0 : sequence of float, optional
        Start for the elastic coordinates (m); default zero.

    Returns
    -------
    OperatingPoint
        ``x = (q, 0)`` and the holding torques ``u`` (N m).

    Raises
    ------
    SolverError
        If Newton does not converge in ``max_iter`` iterations.
    """
    n, N = model.n_u, model.n_q
    qr = np.asarray(q_joints, dtype=float).ravel()
    if qr.size != n:
        raise SpecError(f"{qr.size} joint angles given; expected {n}", key="q_joints")
    warn_if_degrees(qr, key="q_joints")
    qf = np.zeros(N - n) if q_flex0 is None else np.asarray(q_flex0, dtype=float).ravel()
    fun = _static_functions(model)
    iterations = 0
    if N > n:
        for iterations in range(1, max_iter + 1):
            r, J, _ = fun(qr, qf)
            step = np.linalg.solve(np.array(J, dtype=float), np.array(r, dtype=float).ravel())
            qf = qf - step
            if np.max(np.abs(step)) <= tol * (1.0 + np.max(np.abs(qf))):
                break
        else:
            raise SolverError(
                f"equilibrium at joints {qr.tolist()} rad: Newton on the elastic coordinates did "
                "not "
                f"converge in {max_iter} iterations (last step {np.max(np.abs(step)):.3g})"
            )
    tau = np.array(fun(qr, qf)[2], dtype=float).ravel()
    x = np.concatenate([qr, qf, np.zeros(N)])
    residual = float(np.max(np.abs(_xdot(model, x, tau))))
    return OperatingPoint(x, tau, "equilibrium", residual, iterations)


# --------------------------------------------------------------------------------------
# sensors
# --------------------------------------------------------------------------------------
def root_curvature_coefficients(model, q_joints: Sequence[float] | None = None) -> list[np.ndarray]:
    """``phi_ij''(0)`` (1/m^2) of every mode of every link: root curvature ``w_i''(0) = sum_j
    phi_ij''(0) q_fij``.

    Taken from, in order: ``model.info["root_curvature"]`` (a list per link), or the
    arm description (``model.spec``) by recomputing the clamped-mass modes at
    ``info["reference_q"]`` (frozen modes) or at ``q_joints`` (scheduled modes,
    frozen at that configuration for the linear output map).

    Raises
    ------
    SpecError
        If the model carries neither (e.g. a hand-built test model).
    """
    info = getattr(model, "info", {}) or {}
    if "root_curvature" in info:
        return [np.asarray(c, dtype=float).ravel() for c in info["root_curvature"]]
    spec = getattr(model, "spec", None)
    if spec is None or "n_modes" not in info:
        raise SpecError(
            f"model '{model.name}' gives no root curvature of its modes (info['root_curvature']) "
            "and "
            "no arm description to compute it from; strain sensors need phi''(0) per mode",
            key="sensors",
        )
    from flexctrl.modal.arm_modes import link_modes

    if info.get("modes") == "scheduled" and q_joints is not None:
        q_ref = np.asarray(q_joints, dtype=float)
    else:
        q_ref = np.asarray(
            info.get("reference_q", spec.configuration_or_default(None)), dtype=float
        )
    out = []
    for i, nf in enumerate(info["n_modes"]):
        if nf == 0:
            out.append(np.zeros(0))
        else:
            out.append(
                np.asarray(
                    link_modes(spec, q_ref, i, nf).shape(0.0, derivative=2), dtype=float
                ).ravel()
            )
    return out


@dataclass(frozen=True, eq=False)
class Sensors:
    """The measurement model of a controller: which sensors, their noise, one Function ``y(x, u)``.

    Build with :meth:`Sensors.build`.  ``measure`` is what a closed loop calls to
    produce the measurement vector a controller's ``step`` expects.

    Attributes
    ----------
    kinds : tuple of str
        Sensor kinds (see :data:`SENSOR_KINDS`), stacked in this order.
    names : tuple of str
        One name per output: ``q1..`` (joints), ``dq1..`` (joint_rates),
        ``kappa1..`` (strain: root curvature, 1/m, links with modes),
        ``tip_x, tip_y`` (m), ``tip_ax, tip_ay`` (m/s^2), ``w1..`` (tip deflections, m),
        or the state names (state).
    noise_std : ndarray
        Standard deviation per output.
    function : casadi.Function
        ``(x, u) -> (y)``.
    """

    kinds: tuple[str, ...]
    names: tuple[str, ...]
    noise_std: np.ndarray
    function: ca.Function = field(repr=False)

    @staticmethod
    def build(
        model,
        kinds: Sequence[str] = ("joints",),
        noise: dict[str, float] | None = None,
        q_joints: Sequence[float] | None = None,
    ) -> Sensors:
        """Sensors of ``kinds`` on ``model`` with noise standard deviations ``noise`` (per kind).

        ``q_joints`` (rad) is the configuration used for the strain-gauge modal
        coefficients of configuration-scheduled models.
        """
        kinds = tuple(kinds)
        if not kinds:
            raise SpecError(
                "no sensors given; allowed: one or more of " + ", ".join(map(repr, SENSOR_KINDS)),
                key="sensors.outputs",
            )
        for k in kinds:
            if k not in SENSOR_KINDS:
                raise SpecError(
                    f"value {k!r} is not a sensor; allowed: {', '.join(map(repr, SENSOR_KINDS))}",
                    key="sensors.outputs",
                )
        if len(set(kinds)) != len(kinds):
            raise SpecError(f"value {list(kinds)!r} repeats a sensor", key="sensors.outputs")
        kinds = tuple(k for k in SENSOR_KINDS if k in kinds)  # canonical order
        noise = {**DEFAULT_NOISE, **(noise or {})}
        n, N = model.n_u, model.n_q
        x = ca.MX.sym("x", model.n_x)
        u = ca.MX.sym("u", n)
        q, qd = x[:N], x[N:]
        pieces, names, std = [], [], []

        def add(expr, labels, sigma):
            pieces.append(expr)
            names.extend(labels)
            std.extend([float(sigma)] * len(labels))

        for kind in kinds:
            if kind == "joints":
                add(q[:n], [f"q{i + 1}" for i in range(n)], noise[kind])
            elif kind == "joint_rates":
                add(qd[:n], [f"dq{i + 1}" for i in range(n)], noise[kind])
            elif kind == "strain":
                coeffs = root_curvature_coefficients(model, q_joints)
                offsets = np.cumsum([n] + [c.size for c in coeffs])
                rows, labels = [], []
                for i, c in enumerate(coeffs):
                    if c.size:
                        rows.append(ca.dot(ca.DM(c), q[int(offsets[i]) : int(offsets[i + 1])]))
                        labels.append(f"kappa{i + 1}")
                if not rows:
                    raise SpecError(
                        f"model '{model.name}' has no elastic coordinates to put strain gauges on",
                        key="sensors.outputs",
                    )
                add(ca.vertcat(*rows), labels, noise[kind])
            elif kind == "tip":
                p, _v = model.functions["tip"](q, qd)
                add(p, ["tip_x", "tip_y"], noise[kind])
            elif kind == "tip_acc":
                _p, v = model.functions["tip"](q, qd)
                add(ca.jtimes(v, x, model.functions["f"](x, u)), ["tip_ax", "tip_ay"], noise[kind])
            elif kind == "deflection":
                w, _dw = model.functions["deflection"](q)
                add(w, [f"w{i + 1}" for i in range(w.shape[0])], noise[kind])
            elif kind == "state":
                add(x, list(state_names(model)), noise[kind])
        function = ca.Function("sensors", [x, u], [ca.vertcat(*pieces)], ["x", "u"], ["y"])
        try:
            function = function.expand()
        except RuntimeError:
            pass
        return Sensors(kinds, tuple(names), np.asarray(std, dtype=float), function)

    @property
    def n_y(self) -> int:
        """Number of outputs."""
        return len(self.names)

    @property
    def full_state(self) -> bool:
        """Whether the sensors measure the whole state (no estimator needed)."""
        return self.kinds == ("state",)

    def evaluate(self, x, u) -> np.ndarray:
        """Noise-free outputs at state ``x`` and input ``u``."""
        return np.array(self.function(x, u), dtype=float).ravel()

    def measure(self, x, u, rng: np.random.Generator | None = None) -> np.ndarray:
        """Outputs at ``(x, u)`` plus Gaussian noise of :attr:`noise_std` (none when ``rng`` is None)."""
        return self.with_noise(self.evaluate(x, u), rng)

    def with_noise(self, y: np.ndarray, rng: np.random.Generator | None) -> np.ndarray:
        """Noise-free outputs ``y`` plus one draw of Gaussian noise of :attr:`noise_std` (none when ``rng`` is None)."""
        if rng is not None:
            y = y + self.noise_std * rng.standard_normal(y.size)
        return y


# --------------------------------------------------------------------------------------
# linearisation
# --------------------------------------------------------------------------------------
class Linearizer:
    """Exact Jacobians of ``model`` with ``sensors``, built once and evaluated at any operating
    point.

    Use for many linearisations of one model (gain scheduling, frequency maps);
    :func:`linearize` builds one and calls it once.  The Jacobian Function is kept with
    the model (:func:`flexctrl.dynamics.model.derived`) for each sensor Function; its dynamics'
    part is built once per model structure (``shared=True``: the same values).
    """

    def __init__(
        self,
        model,
        outputs: Sequence[str] | Sensors = ("joints",),
        *,
        q_joints: Sequence[float] | None = None,
    ):
        self.model = model
        self.sensors = (
            outputs
            if isinstance(outputs, Sensors)
            else Sensors.build(model, outputs, q_joints=q_joints)
        )
        # kept per model and sensor Function (building the AD graph costs more than a linearisation)
        self.function = derived(
            model,
            ("jacobians", self.sensors.function.serialize()),
            lambda: jacobian_function(
                model, inputs=True, outputs=self.sensors.function, shared=True
            ),
        )

    def matrices(self, op: OperatingPoint) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(A, B, C, D)`` at ``op``."""
        return tuple(np.array(m, dtype=float) for m in self.function(op.x, op.u))  # type: ignore[return-value]

    def __call__(self, op: OperatingPoint, *, name: str | None = None) -> control.StateSpace:
        """The linearisation at ``op`` (see :func:`linearize`)."""
        A, B, C, D = self.matrices(op)
        return control.ss(
            A,
            B,
            C,
            D,
            states=list(state_names(self.model)),
            inputs=list(input_names(self.model)),
            outputs=list(self.sensors.names),
            name=_system_name(name or f"{self.model.name} linearised"),
        )


def linearize(
    model,
    op: OperatingPoint,
    outputs: Sequence[str] | Sensors = ("joints",),
    *,
    name: str | None = None,
) -> control.StateSpace:
    """The linearisation of ``model`` at ``op`` as a continuous ``control.StateSpace``.

    Parameters
    ----------
    model : Model
    op : OperatingPoint
    outputs
        Sensor kinds (see :data:`SENSOR_KINDS`) or a built :class:`Sensors`.
    name
        System name.

    Returns
    -------
    control.StateSpace
        ``d(dx)/dt = A dx + B du``, ``dy = C dx + D du`` with exact AD Jacobians,
        states ``q1.., qf11.., dq1.., dqf11..``, inputs ``tau1..``, outputs as named
        by the sensors.
    """
    return Linearizer(model, outputs, q_joints=op.joints)(op, name=name)


def _system_name(text: str) -> str:
    """python-control forbids '.' in system names."""
    return text.replace(".", "_")


def discretize(sys: control.StateSpace, dt: float, method: str = "zoh") -> control.StateSpace:
    """Sample ``sys`` with period ``dt`` (s), zero-order hold by default; signal names are kept.

    Parameters
    ----------
    sys : control.StateSpace
        A continuous system (e.g. from :func:`linearize`).
    dt : float
        Sample time, s (> 0).
    method : str
        ``control.sample_system``'s method (``"zoh"``, ``"tustin"``, ...).

    Returns
    -------
    control.StateSpace
        The discrete system, ``sys.dt == dt``.
    """
    if not (dt > 0 and math.isfinite(dt)):
        raise SpecError(
            f"value {dt!r} is not allowed; allowed: a sample time > 0 s", key="sample_time"
        )
    return control.sample_system(sys, dt, method=method, name=_system_name(f"{sys.name} sampled"))


# --------------------------------------------------------------------------------------
# modal facts
# --------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ModalSummary:
    """Natural frequencies and damping of a linear system's eigenvalues.

    One entry per complex-conjugate pair (the member with positive imaginary part)
    and per real eigenvalue, sorted by natural frequency.

    Attributes
    ----------
    eigenvalues : ndarray (complex)
        Continuous-time eigenvalues (for a discrete system: ``log(z) / dt``), 1/s.
    frequency_hz : ndarray
        Undamped natural frequencies ``|s| / 2 pi``, Hz.
    damping : ndarray
        Damping ratios ``-Re(s) / |s|`` (NaN for a zero eigenvalue).
    """

    eigenvalues: np.ndarray
    frequency_hz: np.ndarray
    damping: np.ndarray

    @property
    def oscillatory(self) -> np.ndarray:
        """Mask of the complex pairs (vibration modes)."""
        return np.abs(self.eigenvalues.imag) > 0

    def rows(self) -> list[dict[str, float]]:
        """One dict per entry: ``frequency_hz``, ``damping``, ``real``, ``imag``."""
        return [
            {
                "frequency_hz": float(f),
                "damping": float(z),
                "real": float(s.real),
                "imag": float(s.imag),
            }
            for s, f, z in zip(self.eigenvalues, self.frequency_hz, self.damping)
        ]


def holding_torque_excess(model, op: OperatingPoint) -> str:
    """Why the holding torques of ``op`` are beyond the model's joint torque limits, or ``""`` when
    they are not.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        Its ``spec.joints`` give the limits (N m); a model without joints has none.
    op : OperatingPoint
        A static equilibrium (:func:`equilibrium`): ``u`` holds it (N m).

    Returns
    -------
    str
        One line naming the joint angles (deg), the torques and the limits (N m), or ``""``.
    """
    limits = np.array(
        [getattr(j, "torque_limit", np.inf) for j in getattr(model.spec, "joints", ())], dtype=float
    )
    u = np.asarray(op.u, dtype=float).ravel()
    if limits.size != u.size or not np.any(np.abs(u) > limits):
        return ""
    over = ", ".join(
        f"joint {i + 1}: |{u[i]:.4g}| > {limits[i]:.4g}" for i in np.flatnonzero(np.abs(u) > limits)
    )
    q = [round(math.degrees(a), 3) for a in np.asarray(op.x, dtype=float)[: u.size]]
    return (
        f"the static equilibrium at q = {q} deg needs holding torques {np.round(u, 3).tolist()} "
        "N m beyond the "
        f"torque limits {limits.tolist()} N m ({over}): no controller can hold the arm there"
    )


def modal_summary(sys: control.StateSpace, tol: float = 1e-9) -> ModalSummary:
    """Frequencies (Hz) and damping ratios of the eigenvalues of ``sys`` (continuous or discrete).

    Parameters
    ----------
    sys : control.StateSpace
        Continuous, or discrete (its eigenvalues mapped by ``s = ln(z) / dt``).
    tol : float
        Relative size below which an imaginary part counts as zero; of each complex pair
        only the member with a positive imaginary part is kept.

    Returns
    -------
    ModalSummary
        ``eigenvalues`` (1/s), ``frequency_hz`` (Hz) and ``damping`` (ratio; negative for
        an unstable mode, NaN at zero), sorted by frequency.
    """
    eig = np.linalg.eigvals(np.asarray(sys.A, dtype=float))
    if control.isdtime(sys, strict=True):
        with np.errstate(divide="ignore"):
            eig = np.log(eig.astype(complex)) / sys.dt
    scale = max(1.0, float(np.max(np.abs(eig), initial=0.0)))
    keep = [s for s in eig if s.imag > tol * scale or abs(s.imag) <= tol * scale]
    s = np.array([complex(v.real, 0.0) if abs(v.imag) <= tol * scale else v for v in keep])
    mag = np.abs(s)
    with np.errstate(invalid="ignore", divide="ignore"):
        zeta = np.where(mag > 0, -s.real / np.where(mag > 0, mag, 1.0), np.nan)
    order = np.argsort(mag, kind="stable")
    return ModalSummary(s[order], mag[order] / (2 * math.pi), zeta[order])


def locked_frequencies(
    model, op: OperatingPoint | None = None, *, include_gravity: bool = False
) -> np.ndarray:
    """Undamped natural frequencies (Hz, ascending) of the structure with the joints clamped.

    Generalised eigenvalues of ``K_ff`` against ``M_ff`` at the configuration of
    ``op`` (default: zero joint angles and deflections).  ``include_gravity`` adds
    the gravitational stiffness ``d g_f / d q_f`` (the linearisation's elastic block).
    Both matrices are symmetrised (:func:`flexctrl.dynamics.amm.locked_spectrum` computes the
    spectrum).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
    op : OperatingPoint, optional
        Where the mass and stiffness matrices are taken.
    include_gravity : bool
        Add the gravitational stiffness of the elastic coordinates.

    Returns
    -------
    numpy.ndarray
        Frequencies, Hz, one per elastic coordinate.
    """
    n, N = model.n_u, model.n_q
    if N == n:
        return np.zeros(0)
    q0 = np.zeros(N) if op is None else np.asarray(op.q, dtype=float)
    M = model.mass_matrix(q0)
    K = stiffness_matrix(model, q0)
    if include_gravity:
        qs = ca.SX.sym("q", N)
        G = np.array(
            ca.Function("dg", [qs], [ca.jacobian(model.functions["g"](qs), qs)])(q0), dtype=float
        )
        K = K + 0.5 * (G + G.T)
    return locked_spectrum(0.5 * (M + M.T), 0.5 * (K + K.T), n) / (2 * math.pi)


__all__ = [
    "OperatingPoint",
    "Sensors",
    "Linearizer",
    "ModalSummary",
    "SENSOR_KINDS",
    "DEFAULT_NOISE",
    "equilibrium",
    "operating_point",
    "linearize",
    "discretize",
    "modal_summary",
    "locked_frequencies",
    "state_names",
    "input_names",
    "stiffness_matrix",
    "torque_limits",
    "root_curvature_coefficients",
]
