"""Sub-commands of the ``flexctrl`` CLI, one module each (``add_parser`` and ``run``)."""
