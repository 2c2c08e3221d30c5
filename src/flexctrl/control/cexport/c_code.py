"""C text from Python values: exact double literals, constant arrays, units, templates.

Every double is printed with ``repr`` (17 significant digits at most), so the C compiler
reads back the very bits Python holds; a controller's constants in C are Python's.
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path

import numpy as np

#: Unit of each measurement channel, by the name's stem (:attr:`Sensors.names`).
UNITS = {
    "q": "rad",
    "dq": "rad/s",
    "kappa": "1/m",
    "tip_x": "m",
    "tip_y": "m",
    "tip_ax": "m/s^2",
    "tip_ay": "m/s^2",
    "w": "m",
}


def unit_of(name: str) -> str:
    """The unit of a measurement channel named as in :attr:`Sensors.names`.

    Parameters
    ----------
    name : str
        ``q1``, ``dq2``, ``kappa1``, ``tip_ax``, ``w3`` ...; a state name for full-state sensors.

    Returns
    -------
    str
    """
    if name in UNITS:
        return UNITS[name]
    for stem in ("kappa", "dqf", "dq", "qf", "q", "w"):
        if name.startswith(stem) and name[len(stem) :].isdigit():
            return {"dqf": "elastic coordinate unit/s", "qf": "elastic coordinate unit"}.get(
                stem, UNITS.get(stem, "")
            )
    return "state unit"


def c_double(value: float) -> str:
    """A C double literal that reads back to the same bits (``HUGE_VAL`` for infinities).

    Raises
    ------
    ValueError
        For NaN: exported data must be finite or infinite.
    """
    value = float(value)
    if math.isnan(value):
        raise ValueError("NaN in exported controller data")
    if math.isinf(value):
        return "HUGE_VAL" if value > 0 else "(-HUGE_VAL)"
    text = repr(value)
    return text if ("e" in text or "." in text) else text + ".0"


def c_array(name: str, values, ctype: str = "double", *, static: bool = False) -> str:
    """``[static] const ctype name[n] = {...};`` row-major (an empty array gets one zero)."""
    flat = np.asarray(values).ravel()
    items = [c_double(v) if ctype == "double" else str(int(v)) for v in flat] or ["0"]
    lines = [", ".join(items[i : i + 4]) for i in range(0, len(items), 4)]
    body = ",\n  ".join(lines)
    prefix = "static " if static else ""
    return f"{prefix}const {ctype} {name}[{len(items)}] = {{\n  {body}\n}};\n"


def template(name: str) -> str:
    """The text of the C source ``name`` shipped beside this module (folder ``c/``)."""
    return resources.files("flexctrl.control.cexport").joinpath("c", name).read_text()


def generate(functions, out: Path, basename: str) -> dict[str, int]:
    """Write ``basename.c``/``.h``: CasADi's self-contained C99 code of ``functions``.

    Parameters
    ----------
    functions : sequence of casadi.Function
        Each becomes a C function of its own name.
    out : Path
        The folder.
    basename : str
        The file name without suffix.

    Returns
    -------
    dict
        The largest work sizes over ``functions``: ``arg``, ``res``, ``iw``, ``w``.
    """
    import casadi as ca

    gen = ca.CodeGenerator(
        f"{basename}.c", {"with_header": True, "casadi_real": "double", "verbose": False}
    )
    for function in functions:
        gen.add(function)
    gen.generate(str(out) + "/")
    return {
        key: max(int(getattr(f, f"sz_{key}")()) for f in functions)
        for key in ("arg", "res", "iw", "w")
    }


__all__ = ["UNITS", "unit_of", "c_double", "c_array", "template", "generate"]
