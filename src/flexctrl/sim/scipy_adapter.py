"""``scipy.integrate.solve_ivp`` behind the :class:`~flexctrl.sim.integrator.Integrator` interface.

``method`` is any solve_ivp method (RK45, DOP853, Radau, BDF, LSODA, ...);
``rtol`` / ``atol`` are passed through.  The right-hand side and, for the
implicit methods, its Jacobian ``df/dx`` are CasADi Functions evaluated from
numpy.  Held torques change only at step boundaries, so each run of identical
samples is one ``solve_ivp`` call with dense output at the grid points: the
solver never steps across a torque discontinuity.
"""

from __future__ import annotations

from typing import Any, ClassVar

import casadi as ca
import numpy as np
from scipy.integrate import solve_ivp

from flexctrl.dynamics.parametric import try_expand
from flexctrl.errors import SimulationError, SpecError
from flexctrl.sim.integrator import Integrator

METHODS = ("RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA")
_USES_JACOBIAN = ("Radau", "BDF", "LSODA")


class ScipyIntegrator(Integrator):
    """``solve_ivp`` with CasADi right-hand side and Jacobian.

    Parameters
    ----------
    model, dt, u_function, chunk, energy_factor
        See :class:`~flexctrl.sim.integrator.Integrator`.
    method : str
        One of ``RK45, RK23, DOP853, Radau, BDF, LSODA``.
    rtol, atol : float
        Tolerances.
    """

    name: ClassVar[str] = "scipy"

    def __init__(
        self,
        model,
        dt: float,
        *,
        u_function: ca.Function | None = None,
        chunk: int = 1000,
        energy_factor: float = 100.0,
        method: str = "RK45",
        rtol: float = 1e-8,
        atol: float = 1e-10,
    ):
        super().__init__(model, dt, u_function=u_function, chunk=chunk, energy_factor=energy_factor)
        if method not in METHODS:
            raise SpecError(
                f"method {method!r} is not allowed; allowed: {', '.join(METHODS)}", key="method"
            )
        for key, value in (("rtol", rtol), ("atol", atol)):
            if not (isinstance(value, (int, float)) and 0 < value < 1):
                raise SpecError(
                    f"{key} = {value!r} is not allowed; allowed: a number in (0, 1)", key=key
                )
        self.method, self.rtol, self.atol = method, float(rtol), float(atol)

    def settings(self) -> dict[str, Any]:
        """Integrator settings plus method and tolerances."""
        return {**super().settings(), "method": self.method, "rtol": self.rtol, "atol": self.atol}

    def _setup(self) -> None:
        f = try_expand(self.model.functions["f"])
        x = ca.MX.sym("x", self.model.n_x)
        u = ca.MX.sym("u", self.model.n_u)
        t = ca.MX.sym("t")
        torque = u if self.u_function is None else u + ca.vec(self.u_function(t))
        xdot = f(x, torque)
        self._rhs = try_expand(ca.Function("rhs", [t, x, u], [xdot]))
        self._jac = try_expand(ca.Function("rhs_jac", [t, x, u], [ca.jacobian(xdot, x)]))

    def _advance(self, x0: np.ndarray, times: np.ndarray, U: np.ndarray) -> tuple[np.ndarray, None]:
        k = U.shape[0]
        out = np.empty((k, x0.size))
        changes = np.flatnonzero(np.any(np.diff(U, axis=0) != 0.0, axis=1)) + 1
        bounds = [0, *changes.tolist(), k]
        x = x0
        rhs, jac = self._rhs, self._jac
        for a, b in zip(bounds[:-1], bounds[1:]):
            u = U[a]
            fun = lambda t, y, u=u: rhs(t, y, u).full().ravel()  # noqa: E731
            extra = {}
            if self.method in _USES_JACOBIAN:
                extra["jac"] = lambda t, y, u=u: jac(t, y, u).full()
            res = solve_ivp(
                fun,
                (times[a], times[b]),
                x,
                method=self.method,
                t_eval=times[a + 1 : b + 1],
                rtol=self.rtol,
                atol=self.atol,
                **extra,
            )
            self.counters["rhs_evaluations"] = self.counters.get("rhs_evaluations", 0) + int(
                res.nfev
            )
            self.counters["jacobian_evaluations"] = self.counters.get(
                "jacobian_evaluations", 0
            ) + int(res.njev)
            if res.status != 0 or res.y.shape[1] != b - a:
                raise SimulationError(
                    f"scipy {self.method} failed between t = {times[a]:.6g} s and "
                    f"{times[b]:.6g} s: {res.message}. " + self.stability_advice()
                )
            out[a:b] = res.y.T
            x = out[b - 1]
            if not np.all(np.isfinite(x)):
                out[b:] = np.nan
                break
        return out, None
