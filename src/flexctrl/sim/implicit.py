"""Implicit, adaptive integrators for stiff cases: SUNDIALS CVODES and IDAS through CasADi.

Both use variable-order BDF with Newton iterations on the exact Jacobian that
CasADi derives from the model, so a stiff elastic coordinate (``omega_max dt``
far beyond RK4's limit) costs accuracy-limited steps, not stability-limited
ones.  The output grid is the integrator's ``dt``.  Held torques enter as parameters,
and each run of identical torque samples is one integrator call, so SUNDIALS
never steps across a torque jump (passing them as CasADi's piecewise-constant
controls on one grid made CVODES fail its error test at the jumps at tight
tolerances); one integrator object per segment length is kept.  A
``u_function(t)`` is evaluated inside the right-hand side with the segment's
start time as a parameter.

Tolerances ``rtol`` / ``atol`` (default 1e-8 / 1e-10) and ``max_num_steps`` are
settable; other SUNDIALS options go through ``options`` verbatim.
"""

from __future__ import annotations

from typing import Any, ClassVar

import casadi as ca
import numpy as np

from flexctrl.dynamics.parametric import try_expand
from flexctrl.errors import SimulationError, SpecError
from flexctrl.sim.integrator import Integrator


class Sundials(Integrator):
    """CVODES (``name = "cvodes"``) or IDAS (``name = "idas"``) via ``casadi.integrator``.

    Parameters
    ----------
    model, dt, u_function, chunk, energy_factor
        See :class:`~flexctrl.sim.integrator.Integrator`.
    rtol, atol : float
        Relative and absolute tolerances.
    max_num_steps : int
        Internal steps allowed per output interval.
    options : dict, optional
        Further ``casadi.integrator`` options.
    """

    name: ClassVar[str] = "cvodes"
    solver: ClassVar[str] = "cvodes"

    def __init__(
        self,
        model,
        dt: float,
        *,
        u_function: ca.Function | None = None,
        chunk: int = 1000,
        energy_factor: float = 100.0,
        rtol: float = 1e-8,
        atol: float = 1e-10,
        max_num_steps: int = 100000,
        options: dict[str, Any] | None = None,
    ):
        super().__init__(model, dt, u_function=u_function, chunk=chunk, energy_factor=energy_factor)
        for key, value in (("rtol", rtol), ("atol", atol)):
            if not (isinstance(value, (int, float)) and 0 < value < 1):
                raise SpecError(
                    f"{key} = {value!r} is not allowed; allowed: a number in (0, 1)", key=key
                )
        self.rtol, self.atol, self.max_num_steps = float(rtol), float(atol), int(max_num_steps)
        self.options = dict(options or {})
        self._integrators: dict[int, ca.Function] = {}

    def settings(self) -> dict[str, Any]:
        """Integrator settings plus tolerances."""
        return {
            **super().settings(),
            "rtol": self.rtol,
            "atol": self.atol,
            "max_num_steps": self.max_num_steps,
        }

    def _setup(self) -> None:
        f = try_expand(self.model.functions["f"])
        x = ca.MX.sym("x", self.model.n_x)
        u = ca.MX.sym("u", self.model.n_u)
        t = ca.MX.sym("t")
        t0 = ca.MX.sym("t0")
        torque = u if self.u_function is None else u + ca.vec(self.u_function(t + t0))
        self._dae = {"x": x, "p": ca.vertcat(t0, u), "t": t, "ode": f(x, torque)}

    def _integrator(self, k: int) -> ca.Function:
        if k not in self._integrators:
            opts = {
                "abstol": self.atol,
                "reltol": self.rtol,
                "max_num_steps": self.max_num_steps,
                **self.options,
            }
            grid = self.dt * np.arange(1, k + 1)
            self._integrators[k] = ca.integrator(
                f"{self.solver}_{k}", self.solver, self._dae, 0.0, grid, opts
            )
        return self._integrators[k]

    def _advance(self, x0: np.ndarray, times: np.ndarray, U: np.ndarray) -> tuple[np.ndarray, None]:
        k = U.shape[0]
        out = np.empty((k, x0.size))
        changes = np.flatnonzero(np.any(np.diff(U, axis=0) != 0.0, axis=1)) + 1
        bounds = [0, *changes.tolist(), k]
        x = x0
        for a, b in zip(bounds[:-1], bounds[1:]):
            integ = self._integrator(b - a)
            try:
                res = integ(x0=x, p=np.concatenate([[times[a]], U[a]]))
            except RuntimeError as exc:
                raise SimulationError(
                    f"{self.name} failed between t = {times[a]:.6g} s and {times[b]:.6g} s: "
                    f"{str(exc).strip().splitlines()[-1]}. " + self.stability_advice((x0,))
                ) from None
            stats = integ.stats()
            self.counters["rhs_evaluations"] = self.counters.get("rhs_evaluations", 0) + int(
                stats.get("nfevals", 0)
            )
            self.counters["internal_steps"] = self.counters.get("internal_steps", 0) + int(
                stats.get("nsteps", 0)
            )
            out[a:b] = np.asarray(res["xf"], dtype=float).T
            x = out[b - 1]
        return out, None


class CVODES(Sundials):
    """SUNDIALS CVODES (BDF for ODEs).

    Parameters
    ----------
    model, dt, u_function, chunk, energy_factor, rtol, atol, max_num_steps, options
        See :class:`Sundials`.
    """

    name: ClassVar[str] = "cvodes"
    solver: ClassVar[str] = "cvodes"


class IDAS(Sundials):
    """SUNDIALS IDAS (BDF for DAEs; here the ODE as an index-0 DAE).

    Parameters
    ----------
    model, dt, u_function, chunk, energy_factor, rtol, atol, max_num_steps, options
        See :class:`Sundials`.
    """

    name: ClassVar[str] = "idas"
    solver: ClassVar[str] = "idas"
