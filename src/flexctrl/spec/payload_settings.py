"""The ``[payload]`` table of a controller file: a payload range instead of one design payload.

An LQR or MPC file with a ``[payload]`` table describes a *payload-aware* controller: it is
designed at every payload of a grid over the range (the LQR gain, the Kalman filter and, for
the MPC, the prediction model at each grid point), identifies the payload on line with a
bank of those Kalman filters (multiple-model estimation scored by innovation likelihood) and
runs the design at the light side of the estimate (:mod:`flexctrl.control.payload`).

File keys (masses in kg, rates in deg/s as every angle in the files)::

    [payload]
    range = [0.0, 4.0]             # kg, the payloads the arm may carry
    grid_step = 0.25               # kg, or grid = [0.0, 0.25, ...] (kg, covering the range)
    prior_mean = 2.0               # kg, default the range's middle
    prior_std = 1.2                # kg, default the std of a uniform law on the range
    temper = 0.1                   # likelihood exponent (< 1 widens an over-confident posterior)
    probability_floor = 1e-6       # each model's posterior is kept above this
    excitation_rate_deg_s = 2.865  # the bank learns only while a joint moves faster than this
    excitation_window = 5          # samples the joint rate is measured over
    err_light_sigmas = 2.0         # design at the grid point at or below mean - this * std
    coriolis = true                # remove the rigid velocity-product torques from the bank's input
    rest_torque_noise = 0.02       # N m, the filters' torque noise while the reference rests
    rest_modal_force_noise = 0.001 # N, their modal force noise then (both or neither)
    rest_delay = 0.2               # s after the reference stops before the filters slow down
    identify_torque_noise = 0.4    # N m, the identification filters' torque noise (both or neither)
    identify_modal_force_noise = 0.5   # N, their modal force noise

>>> PayloadSettings().grid_points()[:3]
(0.0, 0.25, 0.5)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from flexctrl.errors import SpecError, keywords_checked
from flexctrl.spec.field_checks import boolean_field, integer_field, number_field
from flexctrl.spec.reader import TableReader

#: Gap (kg) below which two grid payloads count as one, and a grid end as the range's end.
GRID_TOLERANCE = 1e-9


@keywords_checked
@dataclass(frozen=True)
class PayloadSettings:
    """How a payload-aware controller covers a payload range (see the module docstring).

    Attributes
    ----------
    range : tuple of float
        ``(lightest, heaviest)`` payload, kg; ``0 <= lightest < heaviest``.
    grid_step : float
        Spacing of a uniform design grid over ``range``, kg (used when ``grid`` is None).
    grid : tuple of float or None
        Explicit design payloads, kg, increasing, from ``range[0]`` to ``range[1]``.
    prior_mean : float or None
        Payload believed before any motion, kg; None: the range's middle.
    prior_std : float or None
        Its standard deviation, kg; None: that of a uniform law on the range,
        ``(heaviest - lightest) / sqrt(12)``.
    temper : float
        Exponent of the innovation likelihood, in (0, 1]: below 1 it widens a posterior the
        linear models would make over-confident (their innovations are not white on the
        nonlinear arm).
    probability_floor : float
        Lower bound of each model's posterior probability, in [0, 0.1): keeps every payload
        alive so a grasp or release is re-identified.
    excitation_rate : float
        The bank updates its probabilities only while some joint moves faster than this,
        rad/s: at rest the innovations carry model error and no payload information.
    excitation_window : int
        Samples over which that joint rate is measured (encoder difference).
    err_light_sigmas : float
        The design runs at the largest grid payload at or below
        ``max(lightest, mean - err_light_sigmas * std)``: over-estimating the payload is the
        unstable side.
    coriolis : bool
        Subtract the rigid model's velocity-product torques (affine in the payload) from the
        torque each filter of the bank sees; the linearisation at rest drops them.
    rest_torque_noise, rest_modal_force_noise : float or None
        The filters' process noise (N m per joint, N per elastic coordinate) while the
        reference rests; None (both): the ``[estimator]`` levels throughout.  From the sample
        the reference stops, each filter's covariance follows the Riccati recursion from the
        moving filter's steady state with these levels (a time-varying Kalman filter): it
        keeps tracking the move's last vibration, then averages the sensor noise over the
        whole time at rest, so the joints are held to a fraction of the encoder noise.
    rest_delay : float
        s from the reference's stop to the filters' slowing down: the move's last transient
        is tracked by the moving filter (a slow filter would turn it into a slow offset).
    identify_torque_noise, identify_modal_force_noise : float or None
        Process noise (N m, N) of a second bank of filters used only to score the payloads;
        None (both): the bank scores the control filters (the ``[estimator]`` levels).  A
        filter that trusts the rigid model more tells the payloads apart better, one that
        follows the sensors more tracks the move better: with these keys each does one job.
        The shipped files trust the joints' model more (0.4 N m) and the elastic model less
        (0.5 N): a fast move loads the links with centrifugal forces the models at rest lack.
    """

    range: tuple[float, float] = (0.0, 4.0)
    grid_step: float = 0.25
    grid: tuple[float, ...] | None = None
    prior_mean: float | None = None
    prior_std: float | None = None
    temper: float = 0.1
    probability_floor: float = 1e-6
    excitation_rate: float = 0.05
    excitation_window: int = 5
    err_light_sigmas: float = 2.0
    coriolis: bool = True
    rest_torque_noise: float | None = None
    rest_modal_force_noise: float | None = None
    rest_delay: float = 0.2
    identify_torque_noise: float | None = None
    identify_modal_force_noise: float | None = None

    def __post_init__(self) -> None:
        low, high = self._checked_range()
        number_field("grid_step", self.grid_step, low=0.0, low_open=True, unit="kg")
        if self.grid is not None:
            self._check_grid(low, high)
        elif self.grid_step > high - low:
            raise SpecError(
                f"value {self.grid_step!r} is wider than the range {list(self.range)}; "
                f"allowed: a step (kg) > 0 and <= {high - low:g}",
                key="grid_step",
            )
        if self.prior_mean is not None:
            number_field("prior_mean", self.prior_mean, low=low, high=high, unit="kg")
        if self.prior_std is not None:
            number_field("prior_std", self.prior_std, low=0.0, low_open=True, unit="kg")
        number_field("temper", self.temper, low=0.0, high=1.0, low_open=True)
        number_field("probability_floor", self.probability_floor, low=0.0, high=0.099)
        number_field("excitation_rate", self.excitation_rate, low=0.0, unit="rad/s")
        integer_field("excitation_window", self.excitation_window, low=1, high=1000)
        number_field("err_light_sigmas", self.err_light_sigmas, low=0.0, unit="standard deviations")
        boolean_field("coriolis", self.coriolis)
        self._check_rest_noise()

    def _check_rest_noise(self) -> None:
        number_field("rest_delay", self.rest_delay, low=0.0, unit="s")
        for prefix in ("rest", "identify"):
            names = (f"{prefix}_torque_noise", f"{prefix}_modal_force_noise")
            pair = tuple(getattr(self, name) for name in names)
            if (pair[0] is None) != (pair[1] is None):
                given = names[0] if pair[1] is None else names[1]
                raise SpecError(
                    f"value {[v for v in pair if v is not None][0]!r} is given alone; allowed: "
                    f"both {names[0]} (N m) and {names[1]} (N), or neither",
                    key=given,
                )
            if pair[0] is not None:
                number_field(names[0], pair[0], low=0.0, unit="N m")
                number_field(names[1], pair[1], low=0.0, unit="N")

    @property
    def rests(self) -> bool:
        """Whether the filters slow down while the reference rests."""
        return self.rest_torque_noise is not None

    @property
    def identifies_apart(self) -> bool:
        """Whether a second bank of filters scores the payloads."""
        return self.identify_torque_noise is not None

    def _checked_range(self) -> tuple[float, float]:
        allowed = "[lightest, heaviest] (kg) with 0 <= lightest < heaviest"
        value = self.range
        if not isinstance(value, tuple) or len(value) != 2:
            raise SpecError(f"value {value!r} is not two numbers; allowed: {allowed}", key="range")
        for i, v in enumerate(value):
            number_field(f"range[{i}]", v, unit="kg")
        low, high = (float(v) for v in value)
        if low < 0.0:
            raise SpecError(f"value {list(value)!r} is negative; allowed: {allowed}", key="range")
        if high <= low:
            what = "empty" if high == low else "reversed"
            raise SpecError(f"value {list(value)!r} is {what}; allowed: {allowed}", key="range")
        return low, high

    def _check_grid(self, low: float, high: float) -> None:
        grid = self.grid
        if not isinstance(grid, tuple) or len(grid) < 2:
            raise SpecError(
                f"value {grid!r} is not allowed; allowed: two or more payloads (kg)", key="grid"
            )
        for i, v in enumerate(grid):
            number_field(f"grid[{i}]", v, unit="kg")
        if any(b - a <= GRID_TOLERANCE for a, b in zip(grid, grid[1:])):
            raise SpecError(
                f"value {list(grid)!r} is not increasing; allowed: increasing payloads (kg)",
                key="grid",
            )
        if abs(grid[0] - low) > GRID_TOLERANCE or abs(grid[-1] - high) > GRID_TOLERANCE:
            raise SpecError(
                f"value {list(grid)!r} does not span the range {list(self.range)}; allowed: "
                f"a grid from {low:g} to {high:g} kg",
                key="grid",
            )

    @property
    def mean0(self) -> float:
        """The prior mean, kg (the range's middle unless given)."""
        low, high = self.range
        return 0.5 * (low + high) if self.prior_mean is None else float(self.prior_mean)

    @property
    def std0(self) -> float:
        """The prior standard deviation, kg (a uniform law's on the range unless given)."""
        low, high = self.range
        return (high - low) / math.sqrt(12.0) if self.prior_std is None else float(self.prior_std)

    def grid_points(self) -> tuple[float, ...]:
        """The design payloads, kg: ``grid``, or ``range`` in steps of ``grid_step``.

        The last step of a uniform grid is shortened to end at the range's end.
        """
        if self.grid is not None:
            return tuple(float(v) for v in self.grid)
        low, high = self.range
        count = int(math.floor((high - low) / self.grid_step + 1e-9))
        points = [round(low + i * self.grid_step, 12) for i in range(count + 1)]
        if high - points[-1] > GRID_TOLERANCE:
            points.append(float(high))
        return tuple(points)


def read_payload(reader: TableReader) -> PayloadSettings | None:
    """The ``[payload]`` table of a controller file, or None when the file has none.

    Parameters
    ----------
    reader : TableReader
        The controller file's top-level table.

    Returns
    -------
    PayloadSettings or None

    Raises
    ------
    SpecError
        Naming the file, the key (``payload.range``, ...), the value and what is allowed.
    """
    if not reader.has("payload"):
        return None
    r = reader.table_of("payload")
    d = PayloadSettings()
    rate_deg = math.degrees(d.excitation_rate)
    values: dict[str, Any] = {
        "range": r.numbers("range", d.range, length=2, unit="kg"),
        "grid_step": r.number("grid_step", d.grid_step, unit="kg"),
        "grid": r.numbers("grid", None, unit="kg") if r.has("grid") else None,
        "prior_mean": r.number("prior_mean", None, unit="kg") if r.has("prior_mean") else None,
        "prior_std": r.number("prior_std", None, unit="kg") if r.has("prior_std") else None,
        "temper": r.number("temper", d.temper),
        "probability_floor": r.number("probability_floor", d.probability_floor),
        "excitation_rate": math.radians(
            r.number("excitation_rate_deg_s", rate_deg, low=0.0, unit="deg/s")
        ),
        "excitation_window": r.integer("excitation_window", d.excitation_window),
        "err_light_sigmas": r.number("err_light_sigmas", d.err_light_sigmas),
        "coriolis": r.boolean("coriolis", d.coriolis),
        "rest_delay": r.number("rest_delay", d.rest_delay, unit="s"),
    }
    for prefix in ("rest", "identify"):
        for name, unit in ((f"{prefix}_torque_noise", "N m"), (f"{prefix}_modal_force_noise", "N")):
            values[name] = r.nonnegative(name, unit=unit) if r.has(name) else None
    if r.has("grid") and r.has("grid_step"):
        raise r.error("grid", "is given with grid_step; allowed: one of grid or grid_step")
    r.finish()
    try:
        return PayloadSettings(**values)
    except SpecError as exc:
        key = "excitation_rate_deg_s" if exc.key == "excitation_rate" else (exc.key or "")
        raise r.error(key, str(exc).split(": ", 1)[1] if exc.key else str(exc)) from None


__all__ = ["PayloadSettings", "read_payload", "GRID_TOLERANCE"]
