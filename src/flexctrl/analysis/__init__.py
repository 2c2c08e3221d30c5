"""Analyses across models, integrators and controllers.

``stability``          largest stable step of an integrator (theory and bisection);
``baumgarte``          Baumgarte feedback on the beam over supports (Jury-test theory, runs);
``accuracy``           converged references and the speed/accuracy points.

Their studies' executors live in :mod:`flexctrl.study.executors`; tip-position errors
between runs are :mod:`flexctrl.sim.tip_error`'s.
"""
