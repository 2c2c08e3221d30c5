"""The largest stable step of an integrator on a model.

``theory``         amplification factors, where rays ``lambda h`` leave the stability region,
                   the classification of eigenvalues and the theoretical step limit
                   (:func:`~.theory.theoretical_step_limit`);
``equilibrium``    the equilibrium a probe perturbs, its linearisation and its modes;
``probe``          probe runs of the real integrator about an equilibrium
                   (:class:`~.probe.StabilityProbe`);
``step_search``    the bisection on probes (:func:`~.step_search.largest_stable_step`);
``limits_report``  the metrics of a search and the table, figure and text of many.
"""
