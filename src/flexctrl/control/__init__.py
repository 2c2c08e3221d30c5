"""Controllers for flexible arms, all with one small protocol
(:class:`~flexctrl.control.controller.Controller`).

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

from flexctrl.control.controller import Controller, ControllerStats
from flexctrl.errors import SpecError
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


def _check_holding_torque(model, op) -> None:
    from flexctrl.linear import holding_torque_excess

    excess = holding_torque_excess(model, op)
    if excess:
        raise SpecError(
            f"{excess}; allowed: a target whose holding torques are within the limits (check "
            "gravity, "
            "the payload and the target)",
            source=getattr(model.spec, "source", None) or None,
            key="target",
        )


#: Controller kind -> ``"module:designer"`` (``designer(model, op, settings) -> Controller``).
DESIGNERS: dict[str, str] = {
    "pd": "flexctrl.control.pd:design_pd",
    "lqr": "flexctrl.control.lqr:design_lqr",
    "mpc": "flexctrl.control.mpc.controller:design_mpc",
    "nmpc": "flexctrl.control.nmpc.controller:design_nmpc",
    "shaped": "flexctrl.control.shaping:design_shaped",
}


#: Controller kind -> ``"module:Class"`` of the controller its designer returns.
CONTROLLER_CLASSES: dict[str, str] = {
    "pd": "flexctrl.control.pd:PDController",
    "lqr": "flexctrl.control.lqr:LQRController",
    "mpc": "flexctrl.control.mpc.controller:MPCController",
    "nmpc": "flexctrl.control.nmpc.controller:NMPCController",
    "shaped": "flexctrl.control.shaping:ShapedController",
}


def has_linear_law(kind: str) -> bool:
    """Whether controllers of ``kind`` give a ``linear_law`` (the linear verdict of :mod:`flexctrl.loop.verdict`)."""
    import importlib

    module, _, name = CONTROLLER_CLASSES[kind].partition(":")
    return callable(getattr(getattr(importlib.import_module(module), name), "linear_law", None))


def design(model, op, settings) -> Controller:
    """Build the controller described by ``settings`` for ``model``, regulating to ``op``.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The design model; the controller keeps it as ``design_model`` (the closed loop
        builds the controller's reference on it).
    op : flexctrl.linear.OperatingPoint
        Target (usually :func:`flexctrl.linear.equilibrium` at the target joint angles).
    settings
        One of the settings dataclasses (see the table in the module docstring), e.g.
        from :func:`flexctrl.spec.controller_reader.load_controller`.

    Returns
    -------
    Controller
        ``step(t, y) -> u`` (N m) for measurements ordered as ``measurement_names``.
    """
    import importlib

    kind = getattr(settings, "kind", None)
    if kind not in DESIGNERS:
        raise SpecError(
            f"value of type {type(settings).__name__} names no controller; allowed: one of "
            f"{', '.join(cls.__name__ for cls in SETTINGS.values())}",
            key="settings",
        )
    _check_holding_torque(model, op)
    module, _, name = DESIGNERS[kind].partition(":")
    controller = getattr(importlib.import_module(module), name)(model, op, settings)
    controller.design_model = model
    return controller


__all__ = [
    "design",
    "has_linear_law",
    "CONTROLLER_CLASSES",
    "Controller",
    "ControllerStats",
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
