"""A designed controller as a self-contained C library for a real-time target.

``ctrl.export_c(DIR)`` (:meth:`~flexctrl.control.controller.Controller.export_c`) writes a
folder that builds with the system C compiler and nothing else: the controller's law in C,
a header with the measurement and torque order and units, the reference table, a
``Makefile`` and a harness that replays a closed loop recorded in Python
(:class:`StepRecorder`) and compares the torques (``make -C DIR check``).  By kind:

- LQR, LQG (:mod:`~flexctrl.control.cexport.law`): CasADi's code generation of the
  controller's own law and estimator; agrees with Python to round-off.
- linear MPC (:mod:`~flexctrl.control.cexport.mpc_dense`): the condensed QP solved by a
  small dense ADMM written for its structure, at a tolerance of its own; agrees with
  Python's OSQP to the QP's tolerance.

Everything here works on the designed controller alone (its law, estimator, QP and
reference), which is why it lives in the control layer beside the controllers, whose
``export_c`` calls it; recording a closed loop is the caller's (``flexctrl export`` runs
the scene's).  This package's ``__init__`` imports no kind's module, so a controller
module may import its kind's exporter without a cycle.
"""

from __future__ import annotations

from flexctrl.control.cexport.library import Export
from flexctrl.control.cexport.replay import Replay, StepRecorder

__all__ = ["Export", "Replay", "StepRecorder"]
