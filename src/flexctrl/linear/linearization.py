"""Linearisation at an operating point and discretisation by zero-order hold.

:func:`linearize` takes exact Jacobians (CasADi AD) at an operating point and returns a
``control.StateSpace`` with named states ``q1.., qf11.., dq1.., dqf11..``, inputs ``tau1..``
and the sensor outputs; :func:`discretize` samples it.  Linear systems are in deviation
variables about the operating point: ``dx = x - op.x``, ``du = u - op.u``,
``dy = y - sensors(op.x, op.u)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import casadi as ca
import control
import numpy as np

from flexctrl.dynamics.jacobians import jacobian_function
from flexctrl.dynamics.model import Model, derived
from flexctrl.errors import SpecError, keyword_checked
from flexctrl.linear.model_facts import input_names, state_names
from flexctrl.linear.operating_point import OperatingPoint
from flexctrl.linear.output_maps import Sensors


class Linearizer:
    """Exact Jacobians of ``model`` with its sensors, built once, evaluated at any operating point.

    Use for many linearisations of one model (gain scheduling, frequency maps);
    :func:`linearize` builds one and calls it once.  The Jacobian Function is kept with
    the model (:func:`flexctrl.dynamics.model.derived`) for each sensor Function, since
    building the AD graph costs more than evaluating it; its dynamics' part is the one kept
    for the model's structure (``shared=True``: the same values).

    Parameters
    ----------
    model : Model
        The model linearised.
    outputs : sequence of str or Sensors
        Sensor kinds (:data:`~flexctrl.spec.sensors.SENSOR_KINDS`) or built sensors.
    q_joints : sequence of float, optional
        Configuration (rad) for the strain gauges of scheduled modes
        (:meth:`Sensors.build`).
    """

    def __init__(
        self,
        model: Model,
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
        sensors = self.sensors.function
        self.function: ca.Function = derived(
            model,
            ("jacobians", sensors.serialize()),
            lambda: jacobian_function(model, inputs=True, outputs=sensors, shared=True),
        )

    def matrices(self, op: OperatingPoint) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(A, B, C, D)`` at ``op``."""
        A, B, C, D = (np.array(m, dtype=float) for m in self.function(op.x, op.u))
        return A, B, C, D

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


@keyword_checked
def linearize(
    model: Model,
    op: OperatingPoint,
    outputs: Sequence[str] | Sensors = ("joints",),
    *,
    name: str | None = None,
) -> control.StateSpace:
    """The linearisation of ``model`` at ``op`` as a continuous ``control.StateSpace``.

    Parameters
    ----------
    model : Model
        The model linearised.
    op : OperatingPoint
        Where (:func:`~flexctrl.linear.operating_point.equilibrium` or a given point).
    outputs : sequence of str or Sensors
        Sensor kinds (see :data:`~flexctrl.spec.sensors.SENSOR_KINDS`) or built
        :class:`Sensors`.
    name : str, optional
        System name (default: the model's name and "linearised").

    Returns
    -------
    control.StateSpace
        ``d(dx)/dt = A dx + B du``, ``dy = C dx + D du`` with exact AD Jacobians,
        states ``q1.., qf11.., dq1.., dqf11..``, inputs ``tau1..``, outputs as named
        by the sensors.
    """
    return Linearizer(model, outputs, q_joints=op.joints.tolist())(op, name=name)


def _system_name(text: str) -> str:
    """python-control forbids '.' in system names."""
    return text.replace(".", "_")


@keyword_checked
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
