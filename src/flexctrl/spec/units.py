"""Degrees in files, radians in Python: the checks that catch one written for the other.

Files and the command line take joint angles in degrees, the Python API radians.  Both
slips are plausible values of the other unit, so neither can be an error; each is a
:class:`~flexctrl.errors.SpecWarning` naming the key, the values and the unit expected:

* a **degree field** (``configuration``, ``initial.q``, ``target.q``, ``target.move``,
  ``design_configuration``, ``theta0``, ``rotation``, a study's ``q<k>`` and
  ``configuration`` values) whose non-zero values are all below 2 pi in magnitude and not
  all whole numbers, e.g. ``move = [0.5236, 0, 0]`` (30 degrees written in radians).
  People write degrees as round numbers, so ``move = [5, 0, 0]`` stays quiet;
* a **radian argument** (:class:`flexctrl.Move`, :func:`flexctrl.equilibrium`) with a value
  above 2 pi in magnitude, e.g. ``target = [30, 0, 0]``.

Weights and tolerances in degrees (``weights.joint_deg = 0.57``) are small on purpose
and are not checked.

>>> looks_like_radians([0.5236, 0, 0]), looks_like_radians([30, 0, 0]), looks_like_radians([5, 0])
(True, False, False)
>>> looks_like_degrees([0.0, 1.5708]), looks_like_degrees([30.0, 0.0])
(False, True)
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from flexctrl.errors import warn_spec

TWO_PI = 2.0 * math.pi


def looks_like_radians(degrees: Iterable[float]) -> bool:
    """Whether angles meant as degrees look like radians (see the module docstring)."""
    nonzero = [abs(float(v)) for v in degrees if v != 0]
    return (
        bool(nonzero) and all(v < TWO_PI for v in nonzero) and any(v != round(v) for v in nonzero)
    )


def looks_like_degrees(radians: Iterable[float]) -> bool:
    """Whether angles meant as radians look like degrees: one above 2 pi in magnitude."""
    return any(abs(float(v)) > TWO_PI + 1e-9 for v in radians)


def warn_if_radians(degrees: Iterable[float], *, source: str | None, key: str) -> None:
    """A :class:`~flexctrl.errors.SpecWarning` when a degree field looks like radians."""
    values = list(degrees)
    if looks_like_radians(values):
        shown = values[0] if len(values) == 1 else values
        in_degrees = [round(math.degrees(v), 3) for v in values]
        warn_spec(
            f"value {shown!r} looks like radians; the unit expected is degrees (in degrees that "
            "would be "
            f"{in_degrees[0] if len(values) == 1 else in_degrees!r})",
            source=source,
            key=key,
            stacklevel=4,
        )


def warn_if_degrees(radians: Iterable[float], *, key: str, source: str | None = None) -> None:
    """A :class:`~flexctrl.errors.SpecWarning` when a radian argument looks like degrees."""
    values = [float(v) for v in radians]
    if looks_like_degrees(values):
        warn_spec(
            f"value {values!r} looks like degrees (above 2 pi); the unit expected is radians (as "
            "radians "
            f"{[round(math.radians(v), 4) for v in values]!r}, e.g. numpy.radians)",
            source=source,
            key=key,
            stacklevel=4,
        )
