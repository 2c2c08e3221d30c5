"""flexctrl: control design for robot arms with flexible links.

Units are SI throughout the Python API and angles are in radians; model, scene
and controller files and the command line take angles in degrees.
"""

from __future__ import annotations

__version__ = "0.1.0"


def load_model(path, payload=None, fidelity="amm:2", **options):
    """Load a model file and build it at ``fidelity`` (see :func:`flexctrl.dynamics.build.load_model`)."""
    from flexctrl.dynamics.build import load_model as _load_model

    return _load_model(path, payload=payload, fidelity=fidelity, **options)


__all__ = ["load_model", "__version__"]
