"""The linear MPC (:class:`MPCController`, designed by :func:`design_mpc`), module by module.

* :mod:`.controller`: the controller (estimate, reference shifts, one QP per sample,
  fall-backs) and :func:`design_mpc`;
* :mod:`.problem`: the scaled problem data (weights, DARE terminal cost, scaling, soft and
  arrival rows);
* :mod:`.qp`: the QP in its sparse (stage-wise) and condensed forms, and move blocking;
* :mod:`.qp_backends`: the QP solvers (OSQP, or a ``casadi.conic`` plugin);
* :mod:`.arrival_search`: minimum-time arrival, the earliest stage the arm can be held in a
  band.
"""

from flexctrl.control.mpc.controller import MPCController, design_mpc

__all__ = ["MPCController", "design_mpc"]
