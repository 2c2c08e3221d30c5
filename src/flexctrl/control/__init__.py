"""Controllers for flexible arms, all with one small protocol (:class:`.Controller`).

``design(model, op, settings)`` builds the controller named by the settings type,
regulating ``model`` to the target equilibrium ``op``
(:func:`flexctrl.linear.equilibrium`); settings come from
:func:`flexctrl.spec.controller_reader.load_controller` or are built in Python.

=========  =================================  ======================================
kind       settings                           controller
=========  =================================  ======================================
pd         :class:`.PDSettings`               :class:`.pd.PDController`
lqr        :class:`.LQRSettings`              :class:`.lqr.LQRController` (LQG, scheduled)
mpc        :class:`.MPCSettings`              :class:`.mpc.MPCController` (OSQP, conic)
nmpc       :class:`.NMPCSettings`             :class:`.nmpc.NMPCController` (RTI, ipopt)
shaped     :class:`.ShapedSettings`           :class:`.shaping.ShapedController` (ZV/ZVD + PD)
=========  =================================  ======================================

Closed loop (sampled, zero-order hold)::

    ctrl = design(model, op, settings)
    ctrl.reset()
    every ctrl.sample_time:  u = ctrl.step(t, ctrl.sensors.measure(x, u, rng))
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable

from flexctrl.control.controller import Controller, ControllerStats
from flexctrl.control.lqr import LQRController, design_lqr
from flexctrl.control.mpc import MPCController, design_mpc
from flexctrl.control.nmpc import NMPCController, design_nmpc
from flexctrl.control.payload.lqr_payload import PayloadLQRController, design_lqr_payload
from flexctrl.control.payload.mpc_payload import PayloadMPCController, design_mpc_payload
from flexctrl.control.pd import PDController, design_pd
from flexctrl.control.sampling_check import sampling_diagnosis
from flexctrl.control.shaping import ShapedController, design_shaped
from flexctrl.errors import DesignWarning, SpecError, keyword_checked
from flexctrl.linear import holding_torque_excess
from flexctrl.spec.controller_settings import (
    SETTINGS,
    EstimatorSettings,
    LQRSettings,
    MPCSettings,
    NMPCSettings,
    OSQPSettings,
    PDSettings,
    ScheduleSettings,
    SensorSettings,
    ShapedSettings,
    Weights,
)
from flexctrl.spec.payload_settings import PayloadSettings


def _check_holding_torque(model, op) -> None:
    excess = holding_torque_excess(model, op)
    if excess:
        raise SpecError(
            f"{excess}; allowed: a target whose holding torques are within the limits "
            "(check gravity, the payload and the target)",
            source=getattr(model.spec, "source", None) or None,
            key="target",
        )


#: Settings type -> the function that designs its controller,
#: ``designer(model, op, settings) -> Controller``.
DESIGNERS: dict[type, Callable[..., Controller]] = {
    PDSettings: design_pd,
    LQRSettings: design_lqr,
    MPCSettings: design_mpc,
    NMPCSettings: design_nmpc,
    ShapedSettings: design_shaped,
}

#: Controller kind -> the class of the controllers its designer returns.
CONTROLLER_CLASSES: dict[str, type[Controller]] = {
    "pd": PDController,
    "lqr": LQRController,
    "mpc": MPCController,
    "nmpc": NMPCController,
    "shaped": ShapedController,
}


def has_linear_law(kind: str) -> bool:
    """Whether controllers of ``kind`` give a ``linear_law``.

    The law the linear verdict of :mod:`flexctrl.loop.verdict` closes with the plant.

    Parameters
    ----------
    kind : {"pd", "lqr", "mpc", "nmpc", "shaped"}
        A controller kind (the settings' ``kind``).

    Returns
    -------
    bool
    """
    return callable(getattr(CONTROLLER_CLASSES[kind], "linear_law", None))


#: Settings type -> the designer of its payload-aware controller (settings with ``payload``).
PAYLOAD_DESIGNERS: dict[type, Callable[..., Controller]] = {
    LQRSettings: design_lqr_payload,
    MPCSettings: design_mpc_payload,
}


def _with_payload_range(settings, payload_range):
    """``settings`` with a ``payload`` table over ``payload_range`` (kg), or as they are."""
    if payload_range is None:
        return settings
    if type(settings) not in PAYLOAD_DESIGNERS:
        raise SpecError(
            f"a payload range does not apply to a {type(settings).__name__}; allowed: "
            f"{', '.join(cls.__name__ for cls in PAYLOAD_DESIGNERS)}",
            key="payload_range",
        )
    table = settings.payload or PayloadSettings()
    values = tuple(payload_range) if isinstance(payload_range, (list, tuple)) else payload_range
    return dataclasses.replace(settings, payload=dataclasses.replace(table, range=values))


@keyword_checked
def design(model, op, settings, *, payload_range=None) -> Controller:
    """Build the controller that ``settings`` describe for ``model``, regulating to ``op``.

    The settings' type names the controller: :class:`PDSettings` designs a
    :class:`PDController`, :class:`LQRSettings` an :class:`LQRController` (LQG with a Kalman
    filter, scheduled with a schedule), :class:`MPCSettings` an :class:`MPCController`,
    :class:`NMPCSettings` an :class:`NMPCController` and :class:`ShapedSettings` a
    :class:`ShapedController` (the table :data:`DESIGNERS`).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model; the controller keeps it as ``design_model`` (the closed loop
        builds the controller's reference on it).
    op : flexctrl.linear.OperatingPoint
        Target (usually :func:`flexctrl.linear.equilibrium` at the target joint angles).
    settings : PDSettings, LQRSettings, MPCSettings, NMPCSettings or ShapedSettings
        E.g. from :func:`flexctrl.spec.controller_reader.load_controller`.  LQR and MPC
        settings with a ``payload`` table design a payload-aware controller
        (:mod:`flexctrl.control.payload`).
    payload_range : tuple of float, optional
        ``(lightest, heaviest)`` payload, kg: design the payload-aware LQR or MPC over it
        (the settings' ``payload`` table, or the defaults of
        :class:`~flexctrl.spec.payload_settings.PayloadSettings`, with this range).

    Returns
    -------
    Controller
        ``step(t, y) -> u`` (N m) for measurements ordered as ``measurement_names``.

    Raises
    ------
    SpecError
        For settings of another type, or a target the torque limits cannot hold.

    Warns
    -----
    DesignWarning
        When the design model has undamped elastic modes or a mode within 3 % (of ``fs/2``)
        of a multiple of half the sample rate (:mod:`flexctrl.control.sampling_check`); the
        controller keeps the diagnosis as ``design_diagnosis`` and a diverging closed loop
        names it.
    """
    designer = DESIGNERS.get(type(settings))
    if designer is None:
        raise SpecError(
            f"value of type {type(settings).__name__} names no controller; allowed: one of "
            f"{', '.join(cls.__name__ for cls in DESIGNERS)}",
            key="settings",
        )
    settings = _with_payload_range(settings, payload_range)
    _check_holding_torque(model, op)
    if getattr(settings, "payload", None) is not None:
        designer = PAYLOAD_DESIGNERS[type(settings)]
    controller = designer(model, op, settings)
    diagnosis = sampling_diagnosis(model, op, settings.sample_time)
    if diagnosis.flagged:
        controller.design_diagnosis = diagnosis
        # stacklevel 3: the caller of design, past the keyword_checked wrapper
        warnings.warn(
            f"'{settings.kind}' controller: {diagnosis.message()}", DesignWarning, stacklevel=3
        )
    return controller


__all__ = [
    "design",
    "has_linear_law",
    "DESIGNERS",
    "CONTROLLER_CLASSES",
    "Controller",
    "ControllerStats",
    "PDController",
    "LQRController",
    "MPCController",
    "NMPCController",
    "ShapedController",
    "PayloadLQRController",
    "PayloadMPCController",
    "design_mpc_payload",
    "PAYLOAD_DESIGNERS",
    "design_lqr_payload",
    "design_pd",
    "design_lqr",
    "design_mpc",
    "design_nmpc",
    "design_shaped",
    "SETTINGS",
    "PDSettings",
    "LQRSettings",
    "MPCSettings",
    "NMPCSettings",
    "ShapedSettings",
    "SensorSettings",
    "Weights",
    "EstimatorSettings",
    "ScheduleSettings",
    "OSQPSettings",
]
