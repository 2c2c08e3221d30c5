"""The sampled-data closed loop: a controller at its own rate on a plant integrated finely.

``plant_step``  the plant's compiled RK4 substeps over one controller sample;
``sampled``     the loop itself (measure, step, hold, advance) and its divergence checks;
``mismatch``    a controller's coordinates and sensors carried onto another plant;
``monitors``    the bounds beyond which a run has diverged;
``verdict``     the linear closed loop's spectral radius (independent of the run);
``metrics``     vibration-suppression metrics and the run's verdicts;
``result``      :class:`~flexctrl.loop.result.ClosedLoopResult`;
``figures``     runs drawn side by side (:func:`flexctrl.compare`);
``api``         :func:`~flexctrl.loop.closed_loop.closed_loop`, the Python entry point.
"""
