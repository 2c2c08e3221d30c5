"""Automatic tuning of a controller file over closed-loop scenarios (``flexctrl tune``,
:func:`flexctrl.tuning`).

``scenarios``   the tuning file's scenario set as a study (the study grid syntax);
``evaluate``    one candidate = the controller file with the tuned keys set, run on every scenario
                through the study backends (local pool or Dask), judged against the constraints;
``optimizers``  the optimisers behind one driver interface (scipy differential evolution, CMA-ES,
                Nelder-Mead), each handed a batch evaluator so a generation runs in parallel;
``controller_file``  the tuned values written into the controller file, comments kept;
``tuner``       the loop, its records (resumable from the run store), ``tuning.json``;
``report``      ``report.md`` with the convergence plot and the before/after table.
"""
