"""Operating points, sensors, linearisation and discretisation of a model.

* :mod:`.operating_point`: :func:`equilibrium` (the joints hold the arm against gravity at
  given angles, the elastic coordinates at their static deflection) and
  :func:`operating_point` (any given state and input).
* :mod:`.output_maps`: :class:`Sensors`, what a real arm measures (joint encoders, joint
  rates, root strain gauges, tip position and acceleration, tip deflections, the full
  state) with its noise, as one CasADi Function ``y(x, u)``.
* :mod:`.linearization`: :func:`linearize` (exact Jacobians, a named ``control.StateSpace``)
  and :func:`discretize` (zero-order hold).
* :mod:`.modal_facts`: :func:`modal_summary` (frequencies and damping of a linear system)
  and :func:`locked_frequencies` (joints clamped: ``K_ff`` against ``M_ff``).
* :mod:`.model_facts`: signal names, the stiffness matrix, joint torque limits.

All quantities are SI; angles in radians.  Linear systems are in deviation variables about
the operating point: ``dx = x - op.x``, ``du = u - op.u``, ``dy = y - sensors(op.x, op.u)``.

Examples
--------
>>> import flexctrl as fc
>>> from flexctrl.linear import equilibrium, linearize
>>> model = fc.load_model("subedi3link", fidelity="amm:1")
>>> op = equilibrium(model, [0.3, -0.2, 0.1])
>>> sys = linearize(model, op, outputs=("joints",))
>>> sys.state_labels[:4], sys.input_labels, sys.output_labels
(['q1', 'q2', 'q3', 'qf11'], ['tau1', 'tau2', 'tau3'], ['q1', 'q2', 'q3'])
"""

from flexctrl.linear.linearization import Linearizer, discretize, linearize
from flexctrl.linear.modal_facts import ModalSummary, locked_frequencies, modal_summary
from flexctrl.linear.model_facts import (
    flexible_index,
    input_names,
    state_names,
    stiffness_matrix,
    torque_limits,
)
from flexctrl.linear.operating_point import (
    OperatingPoint,
    equilibrium,
    holding_torque_excess,
    operating_point,
)
from flexctrl.linear.output_maps import Sensors, root_curvature_coefficients
from flexctrl.spec.sensors import DEFAULT_NOISE, SENSOR_KINDS

__all__ = [
    "OperatingPoint",
    "Sensors",
    "Linearizer",
    "ModalSummary",
    "SENSOR_KINDS",
    "DEFAULT_NOISE",
    "equilibrium",
    "operating_point",
    "holding_torque_excess",
    "linearize",
    "discretize",
    "modal_summary",
    "locked_frequencies",
    "state_names",
    "input_names",
    "stiffness_matrix",
    "torque_limits",
    "flexible_index",
    "root_curvature_coefficients",
]
