"""Model families (rigid limit, assumed modes, finite elements), all presenting :class:`Model`."""

from flexctrl.dynamics.model import Model

__all__ = ["Model"]
