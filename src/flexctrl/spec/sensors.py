"""Sensor kinds and their default noise levels.

Plain facts the controller files (:mod:`flexctrl.spec.controller_shared`) and the models'
output maps (:mod:`flexctrl.linear`) share.
"""

from __future__ import annotations

from typing import Literal

#: Sensor kinds a measurement may hold, in the order their outputs are stacked.
SENSOR_KINDS = ("joints", "joint_rates", "strain", "tip", "tip_acc", "deflection", "state")
SensorKind = Literal["joints", "joint_rates", "strain", "tip", "tip_acc", "deflection", "state"]

#: Default noise standard deviations per sensor kind (units of the output).
DEFAULT_NOISE = {
    "joints": 1.0e-4,  # rad, an encoder with ~2^16 counts per revolution
    "joint_rates": 1.0e-3,  # rad/s
    "strain": 1.0e-4,  # 1/m root curvature (strain 1e-6 for a 20 mm half-height)
    "tip": 1.0e-3,  # m (camera or laser tracker)
    "tip_acc": 5.0e-2,  # m/s^2 (MEMS accelerometer)
    "deflection": 1.0e-4,  # m
    "state": 0.0,
}
