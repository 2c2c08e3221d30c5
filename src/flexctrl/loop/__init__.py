"""The sampled-data closed loop: a controller at its own rate on a plant integrated finely.

``plant_step``     the plant's compiled RK4 substeps over one controller sample;
``sampled``        the loop itself (measure, step, hold, advance), its trajectory;
``plant``          :class:`~flexctrl.loop.plant.Plant`, the arm stepped a sample at a time;
``run_state``      one run's states, torques, samples done and divergence;
``compiled``       the samples chained in CasADi, for laws that are CasADi maps;
``mismatch``       a controller's coordinates and sensors carried onto another plant;
``monitors``       the bounds beyond which a run has diverged;
``verdict``        the linear closed loop's spectral radius (independent of the run);
``metrics``        vibration-suppression metrics and the run's verdicts;
``run_summary``    a run judged and described (``summary.json``);
``result``         :class:`~flexctrl.loop.result.ClosedLoopResult`;
``compare_figure`` runs drawn side by side (:func:`flexctrl.compare`);
``closed_loop``    :func:`~flexctrl.loop.closed_loop.closed_loop`, the Python entry point.
"""
