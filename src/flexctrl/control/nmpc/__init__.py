"""The nonlinear MPC (:class:`NMPCController`, designed by :func:`design_nmpc`), module by module.

* :mod:`.controller`: the controller (state, reference cost, fall-backs) and
  :func:`design_nmpc`;
* :mod:`.prediction_model`: the model predicted with, the design model or its Galerkin
  truncation, and the map of the design state onto it;
* :mod:`.interval`: the shooting interval (RK4 over one sample) and its sensitivities, and the
  horizon's linearization, compiled once per model structure;
* :mod:`.casadi_functions`: the variables' layout and every CasADi Function of a design (QP
  assembly, QP solver, cost and bounds, first guess, full NLP);
* :mod:`.rti`: one real-time iteration, its two calls per sample through bound buffers;
* :mod:`.screened_qp`: the QP tried first without its soft rows;
* :mod:`.hpipm_ocp`: HPIPM called directly on the screened QP;
* :mod:`.nlp`: the first guess's rollout and the full NLP (IPOPT).
"""

from flexctrl.control.nmpc.controller import NMPCController, design_nmpc
from flexctrl.control.nmpc.interval import RK4_BOUND, auto_substeps, interval_functions

__all__ = ["NMPCController", "design_nmpc", "interval_functions", "auto_substeps", "RK4_BOUND"]
