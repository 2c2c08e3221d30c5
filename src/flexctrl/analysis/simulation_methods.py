"""Simulation methods: a model fidelity and an integrator with its step or tolerance, spelt as
one string (see :mod:`flexctrl.analysis.accuracy` for the grammar)."""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from typing import Any

from flexctrl.errors import SpecError

#: Integrators a method may name.
INTEGRATORS = ("rk4", "newmark", "cvodes", "idas", "scipy")
#: solve_ivp methods for ``scipy:VARIANT``.
SCIPY_METHODS = ("RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA")
#: RK4's safe ``omega h`` for ``@stable`` (the imaginary-axis limit is 2.83).
RK4_SAFETY = 2.4
#: Output sample interval (s) shared by every method and the reference.
OUTPUT_DT = 1e-3
#: A state component beyond this (m, rad, m/s, rad/s) counts as diverged.
DIVERGED = 1e6

_METHOD = re.compile(
    r"^(?P<fid>[a-z]+(?::\d+)?)(?P<sched>\+sched)?/(?P<integ>[a-z0-9]+)"
    r"(?::(?P<variant>[A-Za-z0-9]+))?(?:@(?P<value>[^@]+))?$"
)
_STEP = re.compile(r"^(?P<num>[0-9.]+(?:e-?\d+)?)(?P<unit>s|ms|us)?$")


@dataclass(frozen=True)
class Method:
    """One simulation method: model and integrator (see the module docstring for the spelling).

    Attributes
    ----------
    fidelity : str
        ``"rigid"``, ``"amm:N"`` or ``"fem:N"``.
    modes : str
        ``"frozen"`` or ``"scheduled"`` (assumed modes only).
    integrator : str
        One of :data:`INTEGRATORS`.
    step : float or None
        Step (s) of ``rk4`` and ``newmark``; None with ``rk4`` means the stable step.
    rtol : float or None
        Relative tolerance of ``cvodes``, ``idas`` and ``scipy`` (``atol = 1e-2 rtol``).
    variant : str or None
        The solve_ivp method of ``scipy``.
    divide : int
        With ``rk4@stable``: the stable step divided by this (``rk4@stable/2``).
    """

    fidelity: str
    modes: str = "frozen"
    integrator: str = "rk4"
    step: float | None = None
    rtol: float | None = None
    variant: str | None = None
    divide: int = 1

    @property
    def label(self) -> str:
        """The method's spelling (parses back to an equal Method)."""
        head = self.fidelity + ("+sched" if self.modes == "scheduled" else "")
        integ = self.integrator + (f":{self.variant}" if self.variant else "")
        if self.integrator in ("rk4", "newmark"):
            value = (
                ("stable" + (f"/{self.divide}" if self.divide > 1 else ""))
                if self.step is None
                else _step_text(self.step)
            )
        else:
            value = f"{self.rtol:g}"
        return f"{head}/{integ}@{value}"

    @property
    def model_label(self) -> str:
        """The model part: fidelity and, for scheduled modes, ``+sched``."""
        return self.fidelity + ("+sched" if self.modes == "scheduled" else "")

    @property
    def integrator_label(self) -> str:
        """The integrator part (after the slash)."""
        return self.label.split("/", 1)[1]

    @property
    def atol(self) -> float | None:
        """Absolute tolerance (m, rad, m/s, rad/s): ``1e-2 rtol``."""
        return None if self.rtol is None else 1e-2 * self.rtol

    def refined(self) -> Method:
        """The same model with a finer time discretisation: half the step, or rtol / 10."""
        if self.step is not None:
            return dataclasses.replace(self, step=self.step / 2)
        if self.integrator == "rk4":
            return dataclasses.replace(self, divide=2 * self.divide)
        if self.rtol is None:
            raise ValueError(f"method {self.label!r} has neither a step nor a tolerance to refine")
        return dataclasses.replace(self, rtol=self.rtol / 10)


def _step_text(step: float) -> str:
    if step >= 1e-3 and abs(step * 1e3 - round(step * 1e3, 3)) < 1e-12:
        return f"{step * 1e3:g}ms"
    return f"{step * 1e6:g}us"


def parse_step(text: str, *, source: str | None = None, key: str | None = None) -> float:
    """A step written ``1ms``, ``250us``, ``0.001s`` or ``1e-3`` (s)."""
    match = _STEP.match(text.strip())
    if not match:
        raise SpecError(
            f"step {text!r} is not allowed; allowed: a positive number with unit s, ms or us "
            "(e.g. 1ms, 250us, 1e-3)",
            source=source,
            key=key,
        )
    value = float(match["num"]) * {"s": 1.0, None: 1.0, "ms": 1e-3, "us": 1e-6}[match["unit"]]
    if not (0 < value <= 0.1):
        raise SpecError(
            f"step {text!r} = {value:g} s is not allowed; allowed: 0 < step <= 0.1 s",
            source=source,
            key=key,
        )
    return value


def parse_method(text: Any, *, source: str | None = None, key: str | None = None) -> Method:
    """Parse a method spelling (see the module docstring).

    Raises
    ------
    SpecError
        Naming the value and what is allowed.
    """
    from flexctrl.spec.fidelity import parse_fidelity

    allowed = (
        "allowed: FIDELITY[+sched]/INTEGRATOR[:VARIANT][@VALUE], e.g. 'amm:2/rk4@1ms', "
        "'fem:4/rk4@stable', "
        "'fem:4/newmark@1ms', 'amm:2/cvodes@1e-6', 'amm:2/scipy:DOP853@1e-6'; integrators: "
        + ", ".join(INTEGRATORS)
    )
    if not isinstance(text, str):
        raise SpecError(f"method {text!r} is not a string; {allowed}", source=source, key=key)
    match = _METHOD.match(text.strip())
    if not match:
        raise SpecError(f"method {text!r} is not spelt right; {allowed}", source=source, key=key)
    fid = parse_fidelity(match["fid"], source=source, key=key)
    if fid.kind not in ("rigid", "amm", "fem"):
        raise SpecError(
            f"method {text!r}: fidelity '{fid}' is not allowed; allowed: rigid, amm:N, fem:N",
            source=source,
            key=key,
        )
    modes = "scheduled" if match["sched"] else "frozen"
    if modes == "scheduled" and fid.kind != "amm":
        raise SpecError(
            f"method {text!r}: '+sched' applies to assumed modes only; allowed: amm:N+sched",
            source=source,
            key=key,
        )
    integ, variant, value = match["integ"], match["variant"], match["value"]
    if integ not in INTEGRATORS:
        import difflib

        hint = difflib.get_close_matches(integ, INTEGRATORS, n=1)
        extra = f" (did you mean '{hint[0]}'?)" if hint else ""
        raise SpecError(
            f"method {text!r}: integrator '{integ}' is not known{extra}; allowed: "
            f"{', '.join(INTEGRATORS)}",
            source=source,
            key=key,
        )
    if variant is not None and integ != "scipy":
        raise SpecError(
            f"method {text!r}: ':{variant}' applies to scipy only", source=source, key=key
        )
    if integ == "scipy":
        variant = variant or "RK45"
        if variant not in SCIPY_METHODS:
            raise SpecError(
                f"method {text!r}: scipy method '{variant}' is not allowed; allowed: "
                f"{', '.join(SCIPY_METHODS)}",
                source=source,
                key=key,
            )
    if integ in ("rk4", "newmark"):
        stable = re.match(r"^stable(?:/(\d+))?$", value or "stable")
        if stable and integ == "rk4":
            divide = int(stable[1] or 1)
            if not 1 <= divide <= 64:
                raise SpecError(
                    f"method {text!r}: divisor {divide} is not allowed; allowed: 1 to 64",
                    source=source,
                    key=key,
                )
            return Method(str(fid), modes, integ, None, None, None, divide)
        if value is None:
            raise SpecError(
                f"method {text!r}: newmark needs a step, e.g. newmark@1ms", source=source, key=key
            )
        return Method(str(fid), modes, integ, parse_step(value, source=source, key=key), None, None)
    rtol = 1e-6 if value is None else _rtol(value, text, source, key)
    return Method(str(fid), modes, integ, None, rtol, variant)


def _rtol(value: str, text: str, source: str | None, key: str | None) -> float:
    try:
        rtol = float(value)
    except ValueError:
        rtol = math.nan
    if not (1e-12 <= rtol <= 1e-2):
        raise SpecError(
            f"method {text!r}: tolerance {value!r} is not allowed; allowed: a relative tolerance "
            "in [1e-12, 1e-2]",
            source=source,
            key=key,
        )
    return rtol


__all__ = [
    "DIVERGED",
    "INTEGRATORS",
    "OUTPUT_DT",
    "RK4_SAFETY",
    "SCIPY_METHODS",
    "Method",
    "parse_method",
    "parse_step",
]
