"""Moved: the FEM report is :mod:`flexctrl.analysis.fem_report` (it runs simulations, so it sits above sim).

The model computations it used live in :mod:`flexctrl.dynamics.fem.spectrum`; they are re-exported
here so that existing importers keep working.  Import them from there.
"""

from flexctrl.dynamics.fem.spectrum import free_joint_radius, locked_amm_hz, locked_fem_hz, rk4_step_for

__all__ = ["free_joint_radius", "locked_amm_hz", "locked_fem_hz", "rk4_step_for"]

if __name__ == "__main__":  # pragma: no cover
    raise SystemExit("the FEM report moved: run python -m flexctrl.analysis.fem_report")
