"""Sensors as output maps: what a real arm measures, as one CasADi Function ``y(x, u)``.

:class:`Sensors` stacks joint encoders, joint rates, strain gauges at the link roots, the
tip position, the tip acceleration, the tip deflections or the full state, each with a
noise standard deviation.  The kinds and their default noise are
:data:`flexctrl.spec.sensors.SENSOR_KINDS` and :data:`~flexctrl.spec.sensors.DEFAULT_NOISE`.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from flexctrl.dynamics.model import Model
from flexctrl.errors import SpecError
from flexctrl.linear.model_facts import state_names
from flexctrl.modal.arm_modes import link_modes
from flexctrl.spec.sensors import DEFAULT_NOISE, SENSOR_KINDS


def root_curvature_coefficients(
    model: Model, q_joints: Sequence[float] | None = None
) -> list[np.ndarray]:
    """Root curvature ``phi_ij''(0)`` (1/m^2) of every mode of every link.

    The root curvature of link i is ``w_i''(0) = sum_j phi_ij''(0) q_fij``.  Taken from, in
    order: ``model.info["root_curvature"]`` (a list per link), or the arm description
    (``model.spec``) by recomputing the clamped-mass modes at ``info["reference_q"]`` (frozen
    modes) or at ``q_joints`` (scheduled modes, frozen at that configuration for the linear
    output map).

    Parameters
    ----------
    model : Model
        The model the strain gauges are on.
    q_joints : sequence of float, optional
        Joint angles (rad) for scheduled modes.

    Returns
    -------
    list of ndarray
        One array per link (empty for a link without modes), 1/m^2 per unit of ``q_f``.

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
            "and no arm description to compute it from; strain sensors need phi''(0) per mode",
            key="sensors",
        )
    if info.get("modes") == "scheduled" and q_joints is not None:
        q_ref = np.asarray(q_joints, dtype=float)
    else:
        q_ref = np.asarray(
            info.get("reference_q", spec.configuration_or_default(None)), dtype=float
        )
    return [
        np.asarray(link_modes(spec, q_ref, i, nf).shape(0.0, derivative=2), dtype=float).ravel()
        if nf
        else np.zeros(0)
        for i, nf in enumerate(info["n_modes"])
    ]


def _checked_kinds(kinds: Sequence[str]) -> tuple[str, ...]:
    """``kinds`` in the order of :data:`SENSOR_KINDS`; refused if empty, unknown or repeated."""
    allowed = ", ".join(map(repr, SENSOR_KINDS))
    if not kinds:
        raise SpecError(
            "no sensors given; allowed: one or more of " + allowed, key="sensors.outputs"
        )
    for k in kinds:
        if k not in SENSOR_KINDS:
            raise SpecError(
                f"value {k!r} is not a sensor; allowed: {allowed}", key="sensors.outputs"
            )
    if len(set(kinds)) != len(kinds):
        raise SpecError(f"value {list(kinds)!r} repeats a sensor", key="sensors.outputs")
    return tuple(k for k in SENSOR_KINDS if k in kinds)


@dataclass(frozen=True)
class _Symbols:
    """The symbols an output map is written in: ``x = (q, qd)`` and ``u`` (MX)."""

    x: ca.MX
    u: ca.MX
    q: ca.MX
    qd: ca.MX


#: One sensor kind's rows: ``(model, symbols, q_joints) -> (y, names)``.
SensorRows = Callable[[Model, _Symbols, Sequence[float] | None], tuple[ca.MX, list[str]]]


def _joints(model: Model, s: _Symbols, q_joints) -> tuple[ca.MX, list[str]]:
    return s.q[: model.n_u], [f"q{i + 1}" for i in range(model.n_u)]


def _joint_rates(model: Model, s: _Symbols, q_joints) -> tuple[ca.MX, list[str]]:
    return s.qd[: model.n_u], [f"dq{i + 1}" for i in range(model.n_u)]


def _strain(model: Model, s: _Symbols, q_joints) -> tuple[ca.MX, list[str]]:
    """Root curvature of every link with modes (1/m): ``kappa_i = sum_j phi_ij''(0) q_fij``."""
    coeffs = root_curvature_coefficients(model, q_joints)
    offsets = np.cumsum([model.n_u] + [c.size for c in coeffs])
    rows, labels = [], []
    for i, c in enumerate(coeffs):
        if c.size:
            rows.append(ca.dot(ca.DM(c), s.q[int(offsets[i]) : int(offsets[i + 1])]))
            labels.append(f"kappa{i + 1}")
    if not rows:
        raise SpecError(
            f"model '{model.name}' has no elastic coordinates to put strain gauges on",
            key="sensors.outputs",
        )
    return ca.vertcat(*rows), labels


def _tip(model: Model, s: _Symbols, q_joints) -> tuple[ca.MX, list[str]]:
    p, _v = model.functions["tip"](s.q, s.qd)
    return p, ["tip_x", "tip_y"]


def _tip_acc(model: Model, s: _Symbols, q_joints) -> tuple[ca.MX, list[str]]:
    _p, v = model.functions["tip"](s.q, s.qd)
    return ca.jtimes(v, s.x, model.functions["f"](s.x, s.u)), ["tip_ax", "tip_ay"]


def _deflection(model: Model, s: _Symbols, q_joints) -> tuple[ca.MX, list[str]]:
    w, _dw = model.functions["deflection"](s.q)
    return w, [f"w{i + 1}" for i in range(w.shape[0])]


def _state(model: Model, s: _Symbols, q_joints) -> tuple[ca.MX, list[str]]:
    return s.x, list(state_names(model))


#: The rows of each sensor kind.
SENSOR_ROWS: dict[str, SensorRows] = {
    "joints": _joints,
    "joint_rates": _joint_rates,
    "strain": _strain,
    "tip": _tip,
    "tip_acc": _tip_acc,
    "deflection": _deflection,
    "state": _state,
}


@dataclass(frozen=True, eq=False)
class Sensors:
    """The measurement model of a controller: which sensors, their noise, one Function ``y(x, u)``.

    Build with :meth:`Sensors.build`.  ``measure`` is what a closed loop calls to
    produce the measurement vector a controller's ``step`` expects.

    Attributes
    ----------
    kinds : tuple of str
        Sensor kinds (see :data:`~flexctrl.spec.sensors.SENSOR_KINDS`), stacked in this order.
    names : tuple of str
        One name per output: ``q1..`` (joints), ``dq1..`` (joint_rates),
        ``kappa1..`` (strain: root curvature, 1/m, links with modes),
        ``tip_x, tip_y`` (m), ``tip_ax, tip_ay`` (m/s^2), ``w1..`` (tip deflections, m),
        or the state names (state).
    noise_std : ndarray
        Standard deviation per output (units of the output).
    function : casadi.Function
        ``(x, u) -> (y)``.
    """

    kinds: tuple[str, ...]
    names: tuple[str, ...]
    noise_std: np.ndarray
    function: ca.Function = field(repr=False)

    @staticmethod
    def build(
        model: Model,
        kinds: Sequence[str] = ("joints",),
        noise: Mapping[str, float] | None = None,
        q_joints: Sequence[float] | np.ndarray | None = None,
    ) -> Sensors:
        """Sensors of ``kinds`` on ``model`` with noise standard deviations ``noise`` (per kind).

        Parameters
        ----------
        model : Model
            The model measured.
        kinds : sequence of str
            Sensor kinds (:data:`~flexctrl.spec.sensors.SENSOR_KINDS`), each at most once;
            stacked in the canonical order whatever the order given.
        noise : mapping of str to float, optional
            Noise standard deviation per kind (units of its outputs); the others take
            :data:`~flexctrl.spec.sensors.DEFAULT_NOISE`.
        q_joints : sequence of float, optional
            Configuration (rad) for the strain gauges' modal coefficients of
            configuration-scheduled models.

        Returns
        -------
        Sensors
        """
        kinds = _checked_kinds(tuple(kinds))
        sigma = {**DEFAULT_NOISE, **(noise or {})}
        x = ca.MX.sym("x", model.n_x)
        u = ca.MX.sym("u", model.n_u)
        symbols = _Symbols(x, u, x[: model.n_q], x[model.n_q :])
        pieces, names, std = [], [], []
        joints = None if q_joints is None else [float(v) for v in q_joints]
        for kind in kinds:
            rows, labels = SENSOR_ROWS[kind](model, symbols, joints)
            pieces.append(rows)
            names.extend(labels)
            std.extend([float(sigma[kind])] * len(labels))
        function = ca.Function("sensors", [x, u], [ca.vertcat(*pieces)], ["x", "u"], ["y"])
        with contextlib.suppress(RuntimeError):  # a model calling non-SX Functions stays MX
            function = function.expand()
        return Sensors(kinds, tuple(names), np.asarray(std, dtype=float), function)

    @property
    def n_y(self) -> int:
        """Number of outputs."""
        return len(self.names)

    @property
    def full_state(self) -> bool:
        """Whether the sensors measure the whole state (no estimator needed)."""
        return self.kinds == ("state",)

    def evaluate(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Noise-free outputs at state ``x`` and input ``u``."""
        return np.array(self.function(x, u), dtype=float).ravel()

    def measure(
        self, x: np.ndarray, u: np.ndarray, rng: np.random.Generator | None = None
    ) -> np.ndarray:
        """Outputs at ``(x, u)`` plus Gaussian noise of :attr:`noise_std` (none without ``rng``)."""
        return self.with_noise(self.evaluate(x, u), rng)

    def with_noise(self, y: np.ndarray, rng: np.random.Generator | None) -> np.ndarray:
        """Noise-free outputs ``y`` plus one draw of Gaussian noise of :attr:`noise_std`.

        No noise is drawn when ``rng`` is None.
        """
        if rng is not None:
            y = y + self.noise_std * rng.standard_normal(y.size)
        return y
