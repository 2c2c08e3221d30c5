"""Input shaping (ZV, ZVD) of joint references: the classical open-loop way to move without
vibration.

A shaper is a train of impulses ``(A_i, t_i)`` with ``sum A_i = 1``; convolving a
reference with it cancels the residual vibration of a mode of natural frequency
``f`` (Hz) and damping ratio ``zeta``.  With ``K = exp(-zeta pi / sqrt(1 - zeta^2))``
and the damped half period ``T/2 = 1 / (2 f sqrt(1 - zeta^2))`` (Singer & Seering 1990)::

    ZV   A = (1, K) / (1 + K)                  t = (0, T/2)
    ZVD  A = (1, 2K, K^2) / (1 + K)^2          t = (0, T/2, T)

Several modes are handled by convolving their shapers.  :class:`ShapedController`
tracks the shaped reference with PD; the shaper is designed from the lowest
vibration modes of the arm at the target, either under the PD loop
(``frequency_source = "closed_loop"``: the lightly damped complex pairs, damping
< 0.3, of the linearisation closed with the continuous PD law and its torque filter) or of the
locked-joint structure (``"locked"``: :func:`flexctrl.linear.locked_frequencies`, undamped).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import control
import numpy as np

from flexctrl.control.pd import PDController, pd_parts
from flexctrl.errors import SpecError
from flexctrl.linear import Linearizer, OperatingPoint, locked_frequencies, modal_summary
from flexctrl.spec.controller_settings import ShapedSettings

#: Damping ratio below which a complex pair of the closed loop counts as vibration.
VIBRATION_DAMPING = 0.3


@dataclass(frozen=True, eq=False)
class Shaper:
    """A train of impulses: amplitudes (sum 1) and times (s, ascending, first 0).

    Parameters
    ----------
    amplitudes : array_like
        The impulses' amplitudes (stored read-only).
    times : array_like
        Their times, s.
    """

    amplitudes: np.ndarray
    times: np.ndarray

    def __post_init__(self) -> None:
        for name in ("amplitudes", "times"):
            value = np.array(getattr(self, name), dtype=float).ravel()
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def duration(self) -> float:
        """Time of the last impulse, s (the delay the shaper adds)."""
        return float(self.times[-1]) if self.times.size else 0.0

    def convolve(self, other: Shaper) -> Shaper:
        """The shaper of both: impulse times added, amplitudes multiplied, coincident merged."""
        t = (self.times[:, None] + other.times[None, :]).ravel()
        a = (self.amplitudes[:, None] * other.amplitudes[None, :]).ravel()
        order = np.argsort(t, kind="stable")
        t, a = t[order], a[order]
        keep_t, keep_a = [t[0]], [a[0]]
        for ti, ai in zip(t[1:], a[1:]):
            if abs(ti - keep_t[-1]) <= 1e-12 * max(1.0, abs(ti)):
                keep_a[-1] += ai
            else:
                keep_t.append(ti)
                keep_a.append(ai)
        return Shaper(np.array(keep_a), np.array(keep_t))

    def apply(self, signal, t: np.ndarray | float) -> np.ndarray:
        """``sum A_i signal(t - t_i)`` for a callable ``signal`` of time (s).

        What ``signal`` gives before time 0 is the caller's business.
        """
        return sum(
            a * np.asarray(signal(np.asarray(t) - ti)) for a, ti in zip(self.amplitudes, self.times)
        )


def _check(frequency_hz: float, zeta: float) -> tuple[float, float]:
    if not (frequency_hz > 0 and math.isfinite(frequency_hz)):
        raise SpecError(
            f"value {frequency_hz!r} is not allowed; allowed: a frequency > 0 Hz", key="frequency"
        )
    if not 0 <= zeta < 1:
        raise SpecError(
            f"value {zeta!r} is not allowed; allowed: a damping ratio in [0, 1)", key="damping"
        )
    return float(frequency_hz), float(zeta)


def zv(frequency_hz: float, zeta: float = 0.0) -> Shaper:
    """Zero-vibration shaper for a mode of natural frequency ``frequency_hz`` and damping ``zeta``.

    Parameters
    ----------
    frequency_hz : float
        The undamped natural frequency, Hz (> 0).
    zeta : float
        The damping ratio, in [0, 1).

    Returns
    -------
    Shaper
        Two impulses half a damped period apart.
    """
    f, z = _check(frequency_hz, zeta)
    K = math.exp(-z * math.pi / math.sqrt(1 - z * z))
    half = 0.5 / (f * math.sqrt(1 - z * z))
    return Shaper(np.array([1.0, K]) / (1 + K), np.array([0.0, half]))


def zvd(frequency_hz: float, zeta: float = 0.0) -> Shaper:
    """Zero-vibration-and-derivative shaper (robust to frequency error).

    Parameters
    ----------
    frequency_hz : float
        The undamped natural frequency, Hz (> 0).
    zeta : float
        The damping ratio, in [0, 1).

    Returns
    -------
    Shaper
        Three impulses half a damped period apart.
    """
    f, z = _check(frequency_hz, zeta)
    K = math.exp(-z * math.pi / math.sqrt(1 - z * z))
    half = 0.5 / (f * math.sqrt(1 - z * z))
    return Shaper(np.array([1.0, 2 * K, K * K]) / (1 + K) ** 2, np.array([0.0, half, 2 * half]))


SHAPERS = {"zv": zv, "zvd": zvd}


def identity_shaper() -> Shaper:
    """One unit impulse at 0 (no shaping)."""
    return Shaper(np.array([1.0]), np.array([0.0]))


def residual_vibration(shaper: Shaper, frequency_hz: float, zeta: float = 0.0) -> float:
    """Residual vibration of a mode: shaped over unshaped impulse response amplitude (analytic).

    Parameters
    ----------
    shaper : Shaper
        The shaper.
    frequency_hz : float
        The mode's undamped natural frequency, Hz.
    zeta : float
        Its damping ratio.

    Returns
    -------
    float
        0 when the shaper cancels the mode, 1 when it does nothing.
    """
    w = 2 * math.pi * frequency_hz
    wd = w * math.sqrt(1 - zeta * zeta)
    tn = shaper.duration
    decay = shaper.amplitudes * np.exp(-zeta * w * (tn - shaper.times))
    return float(
        math.hypot(
            np.sum(decay * np.cos(wd * shaper.times)), np.sum(decay * np.sin(wd * shaper.times))
        )
    )


def shaping_modes(
    model, op: OperatingPoint, settings: ShapedSettings, kp: np.ndarray, kd: np.ndarray
) -> list[tuple[float, float]]:
    """``(frequency_hz, zeta)`` of the modes to shape (see the module docstring).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model.
    op : OperatingPoint
        The target.
    settings : ShapedSettings
        How many modes, and where their frequencies come from.
    kp, kd : ndarray
        The PD's gains (N m/rad, N m s/rad), for the modes under the PD loop.

    Returns
    -------
    list of (float, float)
        Frequency (Hz) and damping ratio of each mode, the lowest first.

    Raises
    ------
    SpecError
        When the model or the loop has fewer vibration modes than asked for.
    """
    if settings.frequency_source == "locked":
        freqs = locked_frequencies(model, op)
        if freqs.size < settings.modes:
            raise SpecError(
                f"value {settings.modes} is not allowed; the model has {freqs.size} locked modes",
                key="modes",
            )
        return [(float(f), 0.0) for f in freqs[: settings.modes]]
    A, B, _C, _D = Linearizer(model, ("joints",)).matrices(op)
    n, N = model.n_u, model.n_q
    gain = np.zeros((n, 2 * N))
    gain[np.arange(n), np.arange(n)] = kp
    gain[np.arange(n), N + np.arange(n)] = kd
    wc = 2 * math.pi * settings.pd.torque_filter
    if wc > 0:  # the PD torque through its low-pass: states (x, f), f' = wc (-K x - f)
        Acl = np.block([[A, B], [-wc * gain, -wc * np.eye(n)]])
    else:
        Acl = A - B @ gain
    summary = modal_summary(
        control.ss(Acl, np.zeros((Acl.shape[0], 1)), np.zeros((1, Acl.shape[0])), 0)
    )
    picks = [
        (float(f), float(z))
        for f, z, osc in zip(summary.frequency_hz, summary.damping, summary.oscillatory)
        if osc and 0 <= z < VIBRATION_DAMPING
    ]
    if len(picks) < settings.modes:
        raise SpecError(
            f"value {settings.modes} is not allowed; the PD loop has {len(picks)} vibration "
            f"modes (complex pairs with damping < {VIBRATION_DAMPING})",
            key="modes",
        )
    return picks[: settings.modes]


def design_shaper(modes: list[tuple[float, float]], kind: str) -> Shaper:
    """The convolution of one ``kind`` shaper per mode.

    Parameters
    ----------
    modes : list of (float, float)
        Frequency (Hz) and damping ratio of each mode.
    kind : {"zv", "zvd", "none"}
        The shaper per mode; ``"none"``: one unit impulse.

    Returns
    -------
    Shaper
    """
    shaper = identity_shaper()
    if kind == "none":
        return shaper
    for f, z in modes:
        shaper = shaper.convolve(SHAPERS[kind](f, z))
    return shaper


class ShapedController(PDController):
    """PD tracking the shaped reference.

    With a smooth reference (a quintic, :meth:`set_reference`) the shaper is convolved
    with the reference's joint path and its feed-forward torques,
    ``q_s(t) = sum_i A_i q_ref(t - t_i)`` (the torques linearly: exact for the rigid
    inertial feed-forward when the inertia along the path is constant, as for a move of
    joint 1 in a horizontal plane).  With a step or no reference it shapes its own
    profile from the joint angles of the first measurement to the target: a step, or a
    ramp over ``move_time`` (the classical shaped step).

    Built by :func:`design_shaped` (through :func:`flexctrl.design`).

    Parameters
    ----------
    settings : ShapedSettings
        The shaper and its PD (``settings.pd``).
    op, sensors, limits, kp, kd, gravity
        As for :class:`~flexctrl.control.pd.PDController`.
    shaper : Shaper
        The impulse sequence (times s, amplitudes summing to 1).
    modes : list of (float, float)
        The shaped modes: (frequency Hz, damping ratio).
    design_model : Model, optional
        The model designed on (:class:`~flexctrl.control.controller.Controller`).
    """

    kind = "shaped"

    def __init__(
        self,
        settings: ShapedSettings,
        op,
        sensors,
        limits,
        kp,
        kd,
        gravity,
        shaper: Shaper,
        modes: list[tuple[float, float]],
        *,
        design_model=None,
    ):
        super().__init__(
            settings.pd, op, sensors, limits, kp, kd, gravity, design_model=design_model
        )
        self.settings = settings
        self.pd_settings = settings.pd
        self.shaper = shaper
        self.modes = modes
        self._start: tuple[float, np.ndarray] | None = None

    def _reset(self) -> None:
        super()._reset()
        self._start = None

    def _profile(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        T = self.settings.move_time
        if T <= 0:
            return (s >= 0).astype(float), np.zeros_like(s)
        return np.clip(s / T, 0.0, 1.0), ((s >= 0) & (s < T)) / T

    @property
    def shapes_reference(self) -> bool:
        """Whether the reference is a smooth path (shaped as given) rather than a step."""
        return self.reference.path.profile != "step"

    def reference_terms(
        self, t: float, q: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        if not self.shapes_reference and self._start is None:
            self._start = (t, np.array(q, dtype=float))
        row = self.reference_table(np.array([t], dtype=float))[0]
        n = self.n_u
        return row[:n], row[n : 2 * n], row[2 * n : 3 * n], row[3 * n :]

    def reference_table(self, times: np.ndarray) -> np.ndarray:
        """Rows ``(q_s, qd_s, u_ref, u_static)`` of the shaped reference at the sample ``times``
        (s).

        A step or no reference is shaped from the joint angles of the first measurement
        (so this needs a :meth:`step` first).
        """
        times = np.asarray(times, dtype=float)
        A = self.shaper.amplitudes
        shifted = times[:, None] - self.shaper.times[None, :]
        if self.shapes_reference:
            q_all, qd_all = (
                v.reshape(shifted.shape + (-1,))
                for v in self.reference.path.derivatives(shifted.ravel(), order=1)
            )
            u_ref, u_static = (
                np.einsum("m,tmn->tn", A, self._torques(shifted, which)) for which in (1, 2)
            )
            return np.hstack(
                [
                    np.einsum("m,tmn->tn", A, q_all),
                    np.einsum("m,tmn->tn", A, qd_all),
                    u_ref,
                    u_static,
                ]
            )
        if self._start is None:
            raise RuntimeError(
                "the shaped controller shapes a step from its first measurement: step it first"
            )
        t0, q0 = self._start
        pos, vel = self._profile((times[:, None] - t0) - self.shaper.times[None, :])
        delta = np.asarray(self.reference.path.q_target) - q0
        _x, _u, u_static = self.reference.window(
            float(times[0]), self.sample_time, times.size, elastic=False
        )
        return np.hstack(
            [q0 + (pos @ A)[:, None] * delta, (vel @ A)[:, None] * delta, u_static, u_static]
        )

    def _torques(self, times: np.ndarray, which: int) -> np.ndarray:
        """Reference torques (u_ref: 1, u_static: 2) at ``times`` (any shape).

        Linearly interpolated on the sample grid.
        """
        Ts = self.sample_time
        k = np.maximum(times, 0.0) / Ts
        k0 = np.floor(k).astype(int)
        frac = (k - k0)[..., None]
        table = self.reference.window(0.0, Ts, int(k0.max()) + 2, elastic=False)[which]
        return (1 - frac) * table[k0] + frac * table[k0 + 1]


def design_shaped(model, op: OperatingPoint, settings: ShapedSettings) -> ShapedController:
    """Build the shaped-reference PD controller moving ``model`` to ``op``.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model.
    op : OperatingPoint
        The target.
    settings : ShapedSettings
        The shaper and its PD.

    Returns
    -------
    ShapedController
    """
    sensors, limits, kp, kd, gravity = pd_parts(model, op, settings.pd)
    modes = [] if settings.shaper == "none" else shaping_modes(model, op, settings, kp, kd)
    shaper = design_shaper(modes, settings.shaper)
    return ShapedController(
        settings, op, sensors, limits, kp, kd, gravity, shaper, modes, design_model=model
    )


__all__ = [
    "Shaper",
    "zv",
    "zvd",
    "identity_shaper",
    "residual_vibration",
    "design_shaper",
    "shaping_modes",
    "ShapedController",
    "design_shaped",
]
