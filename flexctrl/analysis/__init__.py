"""Analyses across models, integrators and controllers (issue 7).

``tip_error``          tip-position error of one run against a reference run;
``stability``          largest stable step of an integrator, found by bisection;
``stability_study``    the ``stability_limits`` study executor;
``baumgarte_study``    the ``baumgarte_sweep`` study executor;
``accuracy``           converged references and the speed/accuracy points;
``accuracy_study``     the ``speed_vs_accuracy`` study executor;
``auto_fidelity``      the cheapest model that meets a scene's tolerance.
"""
