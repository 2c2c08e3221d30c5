"""Time integration of :class:`~flexctrl.dynamics.model.Model` objects.

Integrators share one template (:class:`~flexctrl.sim.integrator.Integrator`) and are
chosen by name or class, like scipy's ``solve_ivp(method=...)``:

``rk4``     fixed-step classical Runge-Kutta, whole horizon in compiled C (:mod:`.rk4`)
``euler``   fixed-step explicit Euler, compiled like rk4 (:mod:`.euler`; unstable on undamped modes)
``newmark`` fixed-step Newmark (average acceleration by default; implicit, Python loop;
            :mod:`.newmark_model`)
``cvodes``  SUNDIALS CVODES, adaptive BDF (:mod:`.implicit`)
``idas``    SUNDIALS IDAS, adaptive BDF (:mod:`.implicit`)
``scipy``   ``scipy.integrate.solve_ivp`` (RK45, DOP853, Radau, BDF, ...) (:mod:`.scipy_adapter`)

Every run returns a :class:`~flexctrl.sim.trajectory.Trajectory`.

Examples
--------
>>> import flexctrl as fc
>>> from flexctrl.sim import simulate
>>> model = fc.load_model("subedi3link", fidelity="rigid", gravity=[0.0, 0.0])
>>> traj = simulate(model, [0.3, 0, 0, 0, 0, 0], 0.1, dt=1e-3, compile=False)
>>> traj.states.shape
(101, 6)
"""

from __future__ import annotations

import difflib
import inspect
from typing import Any

from flexctrl.errors import SpecError, keyword_checked
from flexctrl.sim.euler import Euler
from flexctrl.sim.implicit import CVODES, IDAS
from flexctrl.sim.integrator import Integrator
from flexctrl.sim.newmark_model import Newmark
from flexctrl.sim.rk4 import RK4
from flexctrl.sim.scipy_adapter import ScipyIntegrator
from flexctrl.sim.trajectory import Trajectory

#: Integrators by name.
INTEGRATORS: dict[str, type[Integrator]] = {
    cls.name: cls for cls in (RK4, CVODES, IDAS, ScipyIntegrator, Euler, Newmark)
}


def get_integrator(method: str | type[Integrator]) -> type[Integrator]:
    """The integrator class of a name (see :data:`INTEGRATORS`), or an :class:`Integrator` class.

    Parameters
    ----------
    method : str or type
        A name of :data:`INTEGRATORS` or an :class:`Integrator` subclass (returned as is).

    Returns
    -------
    type
        The integrator class.

    Raises
    ------
    SpecError
        When the name is not known.
    """
    if isinstance(method, type) and issubclass(method, Integrator):
        return method
    if isinstance(method, str) and method in INTEGRATORS:
        return INTEGRATORS[method]
    hint = difflib.get_close_matches(str(method), list(INTEGRATORS), n=1)
    extra = f" (did you mean '{hint[0]}'?)" if hint else ""
    raise SpecError(
        f"integrator {method!r} is not known; allowed: {', '.join(map(repr, INTEGRATORS))} "
        f"or an Integrator subclass{extra}",
        key="integrator",
    )


@keyword_checked
def simulate(
    model,
    x0,
    duration: float,
    *,
    dt: float,
    method: str | type[Integrator] = "rk4",
    u=None,
    **options: Any,
) -> Trajectory:
    """Integrate ``model`` from ``x0`` for ``duration`` seconds and return the :class:`Trajectory`.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
    x0 : array_like
        Initial state ``(q, qd)`` (rad, m, rad/s, m/s).
    duration : float
        Simulated time (s).
    dt : float
        Step / output interval and torque hold period (s).
    method : str or Integrator subclass
        ``"rk4"`` (default), ``"cvodes"``, ``"idas"``, ``"scipy"``, ``"euler"``, ``"newmark"`` or
        a class.
    u : array_like, optional
        Held joint torques (N m), shape (n_steps, n_u) or (n_u,).
    **options
        Passed to the integrator (``u_function``, ``compile``, ``rtol``, ``alpha`` and ``delta``
        for newmark, ``method`` for scipy is given as ``scipy_method``, ...).
    """
    cls = get_integrator(method)
    if "scipy_method" in options:
        options["method"] = options.pop("scipy_method")
    _check_options(cls, options)
    return cls(model, dt, **options).run(x0, duration, u=u)


def _check_options(cls: type[Integrator], options: dict[str, Any]) -> None:
    """A :class:`TypeError` naming the options ``cls`` takes when ``options`` has another."""
    parameters = inspect.signature(cls.__init__).parameters.values()
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters):
        return
    kinds = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    allowed = [p.name for p in parameters if p.kind in kinds and p.name not in ("self", "model")]
    allowed = ["scipy_method" if name == "method" else name for name in allowed if name != "dt"]
    for name in options:
        if (name == "method" and "scipy_method" in allowed) or name in allowed:
            continue
        close = difflib.get_close_matches(name, allowed, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise TypeError(
            f"simulate() got an unexpected option {name!r} for the {cls.__name__} integrator"
            f"{hint}; allowed: dt, method, u, {', '.join(allowed)}"
        )


__all__ = [
    "Integrator",
    "RK4",
    "CVODES",
    "IDAS",
    "ScipyIntegrator",
    "Euler",
    "Newmark",
    "Trajectory",
    "INTEGRATORS",
    "get_integrator",
    "simulate",
]
