"""The largest stable step of an integrator on a model.

``theory``   amplification factors, where rays ``lambda h`` leave the stability region, the
             classification of eigenvalues and the theoretical step limit
             (:func:`~.theory.theoretical_step_limit`);
``probe``    the measurement: probe runs of the real integrator about an equilibrium
             (:class:`~.probe.StabilityProbe`) and the bisection
             (:func:`~.probe.largest_stable_step`).
"""
