"""Moved to :mod:`flexctrl.dynamics.fem.newmark_dae` (the finite-element models in dynamics use it).

This name is kept so that existing importers keep working; import from the new home.
"""

from flexctrl.dynamics.fem.newmark_dae import (ConstraintViolationError, DAEProblem, DAEResult,
                                               NewtonConvergenceError, casadi_problem, simulate)

__all__ = ["ConstraintViolationError", "DAEProblem", "DAEResult", "NewtonConvergenceError", "casadi_problem",
           "simulate"]
