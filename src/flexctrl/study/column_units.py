"""Units of a study's columns as a reader sees them: ``tip residual RMS (mm)``, ``q2 (deg)``.

A study table holds SI values (m, s, rad, N m; grid angles in degrees as written in
the study file).  The report shows lengths in mm, angles in degrees and controller
computing times in ms; :func:`display` gives the label and the factor from the
table's value to the shown one.  Units come from the metric's definition
(:data:`flexctrl.loop.metrics.UNITS` for the closed loop), the grid's own
conventions (payload in kg, joint angles in degrees) and, for other executors'
metrics, their documented units (:data:`OTHER_UNITS`).  A column of unknown unit
is labelled with its name alone.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from flexctrl.loop.metrics import JOINT_METRICS, METRIC_INFO, MetricInfo
from flexctrl.loop.metrics import UNITS as LOOP_UNITS

#: SI units of grid coordinates and of the other shipped executors' metrics (their docstrings).
OTHER_UNITS = {
    "payload": "kg",
    "replicate": "",
    "tip_error_rms": "m",
    "tip_error_max": "m",
    "wall_per_sim_s": "s/s",
    "wall_per_sim_s_spread": "s/s",
    "setup_s": "s",
    "omega_max": "rad/s",
    "omega_max_model": "rad/s",
    "tip_travel": "m",
    "ref_wall_per_sim_s": "s/s",
    "ref_step2_rms": "m",
    "ref_step2_max": "m",
    "ref_fem4_rms": "m",
    "ref_fem4_max": "m",
    "h_measured": "s",
    "h_cap": "s",
    "h_floor": "s",
    "omega_h_measured": "-",
    # stored trajectories: the closed loop's (t, e, tip_x, tip_y, q1.., u1.., w1..) and the
    # selftest's
    "t": "s",
    "e": "m",
    "tip_x": "m",
    "tip_y": "m",
    "q": "rad",
    "u": "N m",
    "w": "m",
    "w_measured": "m",
    "w_dot": "m/s",
    "frequency_hz": "Hz",
    "wall_time_s": "s",
    "peak_memory_mb": "MB",
    "bytes_written": "B",
    "window_start": "s",
    "torque_limit": "N m",
}

#: SI unit -> (shown unit, factor from SI to it).
_SHOWN = {"m": ("mm", 1e3), "rad": ("deg", 57.29577951308232), "s": ("s", 1.0)}
_JOINT = re.compile(r"^q[1-9][0-9]?$")
_PER_JOINT = re.compile(r"^(.*?)_?([1-9][0-9]?)$")
_WORDS = {"rms": "RMS", "p95": "95th percentile"}
#: Names whose words alone would mislead: 0/1 verdicts say which value is which.
_NAMES = {
    "stable": "stable (1 = yes, 0 = no)",
    "settled_within_band": "settled within the band (1 = yes, 0 = no)",
    "settled": "settled (1 = yes, 0 = no)",
    "closed_loop_radius": "closed-loop spectral radius (< 1: stable)",
    "torque_limit_exceeded": "torque limit exceeded (1 = yes)",
}
#: Trailing words of a name that spell its unit (``wall_time_s``), left out of the label.
_UNIT_WORDS = ("s", "hz", "mb", "kg")


@dataclass(frozen=True)
class Shown:
    """How a column is shown: its ``label`` with the unit, and ``scale`` from table value to shown
    value."""

    name: str
    unit: str
    scale: float

    @property
    def label(self) -> str:
        """``"tip residual RMS (mm)"``; no parentheses for a count, a 0/1 verdict or an unknown
        unit."""
        if self.name in _NAMES:
            return _NAMES[self.name]
        parts = self.name.split("_")
        if self.unit and len(parts) > 1 and parts[-1] in _UNIT_WORDS:
            parts = parts[:-1]
        words = " ".join(_WORDS.get(w, w) for w in parts)
        return f"{words} ({self.unit})" if self.unit else words

    def value(self, value):
        """The shown value of a table value (non-numbers pass through)."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return value
        return value * self.scale


def si_unit(column: str, *, trajectory: bool = False) -> str | None:
    """The unit of a table column, or of a stored trajectory with ``trajectory`` (None if unknown).

    Grid joint angles ``q2`` are in degrees as the study file writes them; a stored
    trajectory ``q2`` is in rad.
    """
    if _JOINT.match(column):
        return "rad" if trajectory else "deg"
    if column in LOOP_UNITS:
        return LOOP_UNITS[column]
    if column in OTHER_UNITS:
        return OTHER_UNITS[column]
    match = _PER_JOINT.match(column)
    if match and (match.group(1) in JOINT_METRICS or match.group(1) in OTHER_UNITS):
        return LOOP_UNITS.get(match.group(1), OTHER_UNITS.get(match.group(1)))
    return None


def metric_info(column: str) -> MetricInfo | None:
    """What a closed-loop metric column is (:data:`flexctrl.loop.metrics.METRIC_INFO`), per-joint
    columns (``peak_torque_2``) included; None for a column it does not describe.

    >>> metric_info("stable").better, metric_info("peak_torque_2").better
    ('higher', 'lower')
    """
    if column in METRIC_INFO:
        return METRIC_INFO[column]
    match = _PER_JOINT.match(column)
    if match and match.group(1) in JOINT_METRICS:
        return METRIC_INFO[match.group(1)]
    return None


def lower_is_better(column: str) -> bool:
    """Whether lower values of ``column`` are better: its :func:`metric_info` direction, lower for
    a column it does not describe (errors, times, costs)."""
    info = metric_info(column)
    return info is None or info.better == "lower"


def display(column: str, *, trajectory: bool = False) -> Shown:
    """How ``column`` is shown in a report (see the module docstring).

    >>> display("tip_residual_rms").label, display("tip_residual_rms").scale
    ('tip residual RMS (mm)', 1000.0)
    >>> display("controller_time_p95").label
    'controller time 95th percentile (ms)'
    >>> display("q2").label, display("payload").label, display("stable").label
    ('q2 (deg)', 'payload (kg)', 'stable (1 = yes, 0 = no)')
    >>> metres_to_mm = display("final_tip_error").scale
    >>> display("q2", trajectory=True).scale == metres_to_mm / 1e3 * 180 / 3.141592653589793
    True
    """
    unit = si_unit(column, trajectory=trajectory)
    if unit is None or unit in ("", "-"):
        return Shown(column, "", 1.0)
    if unit == "s" and column.startswith("controller_time"):
        return Shown(column, "ms", 1e3)
    shown, scale = _SHOWN.get(unit, (unit, 1.0))
    return Shown(column, shown, scale)


def with_unit(column: str, value) -> str:
    """``"payload = 2 kg"``, ``"q2 = 45 deg"``, ``"controller = lqr"``: a coordinate as a reader
    reads it."""
    shown = display(column)
    number = shown.value(value)
    text = f"{number:g}" if isinstance(number, float) else str(number)
    return f"{column} = {text}" + (
        f" {shown.unit}" if shown.unit and isinstance(number, (int, float)) else ""
    )
