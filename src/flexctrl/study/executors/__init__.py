"""The shipped study executors, one module each (registered in :mod:`flexctrl.study.registry`).

Each module has ``execute(settings) -> RunOutput`` and optionally
``check_settings(settings)`` and ``report_sections(directory, rows, figures)``.
"""
