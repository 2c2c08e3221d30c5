"""The integrator template: bookkeeping in :class:`Integrator`, stepping in subclasses.

As in scipy's ``OdeSolver`` (``step()`` does the bookkeeping, ``_step_impl()`` the
work), :meth:`Integrator.run` validates the initial state and inputs, lays out the
time grid, cuts the horizon into chunks (``chunk`` steps, 1000 by default, so
memory and divergence checks stay bounded), evaluates energies, tip positions and
deflections with a mapped CasADi function, watches for divergence and assembles a
:class:`~flexctrl.sim.trajectory.Trajectory`.  A subclass implements one of

``_step(x, t, u) -> x_next``
    one step (the default ``_advance`` loops over it), or
``_advance(x0, times, U) -> (X, Y | None)``
    a whole chunk at once (compiled loops, SUNDIALS grids, ``solve_ivp``);

and optionally ``_setup()`` (build and compile, done once, timed apart from the run).

Inputs are joint torques: samples held constant over each step (zero-order
hold, shape ``(n_steps, n_u)``) plus, optionally, a CasADi Function of time
``u_function(t) -> (n_u,)`` added to them and evaluated where the method samples
the dynamics (RK4 stages, adaptive steps).

Divergence (a non-finite state, or kinetic plus elastic energy above
``energy_factor`` times the energy the run can account for: the initial kinetic
and elastic energy, the range of gravitational energy seen, and the work the
torques did) raises :class:`~flexctrl.errors.SimulationError` naming the time,
the step, the model's ``omega_max`` and a stable step or another integrator.
"""

from __future__ import annotations

import math
import time
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from flexctrl.dynamics.jacobians import jacobian_function
from flexctrl.dynamics.parametric import try_expand
from flexctrl.errors import SpecError
from flexctrl.sim.divergence import DivergenceMonitor
from flexctrl.sim.trajectory import Trajectory

#: Rows of the output vector y(x) evaluated along a trajectory.
OUTPUT_ROWS = ("E_kin", "E_el", "E_grav", "tip_x", "tip_y")  # then w1..w_nlinks


def output_function(model, energies: bool = True) -> ca.Function:
    """``y(x) = (E_kin, E_el, E_grav, tip_x, tip_y, w_1..w_n)`` of a model, as one Function.

    The kinetic energy needs the mass matrix, so it costs most of the outputs.

    Parameters
    ----------
    model : Model
        The arm.
    energies : bool
        Include the energies (J); ``False`` gives ``(tip_x, tip_y, w_1..w_n)`` (m) alone,
        named ``kinematic_outputs``.

    Returns
    -------
    casadi.Function
        ``y(x)``, energies in J, tip position and tip deflections in m.
    """
    x = ca.MX.sym("x", model.n_x)
    q, qd = x[: model.n_q], x[model.n_q :]
    p, _v = model.functions["tip"](q, qd)
    w, _dw = model.functions["deflection"](q)
    rows = [*(model.functions["energies"](q, qd) if energies else ()), ca.vec(p)[:2], ca.vec(w)]
    name = "outputs" if energies else "kinematic_outputs"
    return try_expand(ca.Function(name, [x], [ca.vertcat(*rows)], ["x"], ["y"]))


def check_input_function(fun: ca.Function | None, n_u: int) -> ca.Function | None:
    """Validate a time-function input ``u(t) -> (n_u,)``.

    Parameters
    ----------
    fun : casadi.Function or None
        Torques (N m) as a function of time (s); ``None`` passes through.
    n_u : int
        Number of torques the model takes.

    Returns
    -------
    casadi.Function or None
        ``fun`` unchanged.

    Raises
    ------
    SpecError
        When ``fun`` is not a Function of one scalar with ``n_u`` torques as first output.
    """
    if fun is None:
        return None
    if not isinstance(fun, ca.Function):
        raise SpecError(
            f"u_function must be a casadi.Function of time, got {type(fun).__name__}",
            key="u_function",
        )
    if fun.n_in() != 1 or fun.numel_in(0) != 1 or fun.n_out() < 1 or fun.numel_out(0) != n_u:
        raise SpecError(
            f"u_function has signature {fun}; expected one scalar input t and a first output of "
            f"{n_u} torques",
            key="u_function",
        )
    return fun


class Integrator:
    """Base class of every integrator (template method; see the module docstring).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The model to integrate (``f`` and the output functions are used).
    dt : float
        Output step and zero-order-hold period of the torque samples (s).
    u_function : casadi.Function, optional
        Torque as a function of time, added to the held samples.
    chunk : int
        Steps per chunk (divergence checks and memory are per chunk).
    energy_factor : float
        Divergence threshold on kinetic plus elastic energy (see module docstring).
    """

    #: Name used by :func:`flexctrl.sim.get_integrator` and in results.
    name: ClassVar[str] = ""
    #: Largest stable ``omega * dt`` on the imaginary axis (explicit methods).
    stability_limit: float = math.inf

    def __init__(
        self,
        model,
        dt: float,
        *,
        u_function: ca.Function | None = None,
        chunk: int = 1000,
        energy_factor: float = 100.0,
    ):
        if (
            isinstance(dt, bool)
            or not isinstance(dt, (int, float))
            or not math.isfinite(dt)
            or dt <= 0
        ):
            raise SpecError(
                f"step dt = {dt!r} is not allowed; allowed: a finite number > 0 (s)", key="dt"
            )
        if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
            raise SpecError(
                f"chunk = {chunk!r} is not allowed; allowed: an integer >= 1 (steps)", key="chunk"
            )
        if not (isinstance(energy_factor, (int, float)) and energy_factor > 1):
            raise SpecError(
                f"energy_factor = {energy_factor!r} is not allowed; allowed: a number > 1",
                key="energy_factor",
            )
        self.model = model
        self.dt = float(dt)
        self.chunk = chunk
        self.energy_factor = float(energy_factor)
        self.u_function = check_input_function(u_function, model.n_u)
        self.setup_seconds = 0.0
        self.counters: dict[str, float] = {}
        self._ready = False
        self._outputs_fn = output_function(model)

    # -- public ---------------------------------------------------------------------------
    def settings(self) -> dict[str, Any]:
        """The options that define this integrator (recorded in results)."""
        return {"integrator": self.name, "dt": self.dt, "chunk": self.chunk}

    def setup(self) -> Integrator:
        """Build (and compile) once; later calls do nothing."""
        if not self._ready:
            start = time.perf_counter()
            self._setup()
            self.setup_seconds = time.perf_counter() - start
            self._ready = True
        return self

    def run(self, x0, duration: float, u=None) -> Trajectory:
        """Integrate from ``x0`` over ``duration`` seconds.

        Parameters
        ----------
        x0 : array_like
            Initial state ``(q, qd)``, shape (2N,).
        duration : float
            Simulated time (s); rounded up to a whole number of steps.
        u : array_like, optional
            Held joint torques (N m): shape (n_steps, n_u), or (n_u,) for a constant.

        Returns
        -------
        Trajectory

        Raises
        ------
        SimulationError
            On divergence (see module docstring).
        """
        model = self.model
        x0 = np.asarray(x0, dtype=float).ravel()
        if x0.shape != (model.n_x,) or not np.all(np.isfinite(x0)):
            raise SpecError(
                f"initial state has shape {x0.shape} (finite: {bool(np.all(np.isfinite(x0)))}); "
                f"expected {model.n_x} finite values (q, qd)",
                key="x0",
            )
        if (
            isinstance(duration, bool)
            or not isinstance(duration, (int, float))
            or not math.isfinite(duration)
            or duration <= 0
        ):
            raise SpecError(
                f"duration {duration!r} is not allowed; allowed: a finite number > 0 (s)",
                key="duration",
            )
        n = max(1, int(math.ceil(duration / self.dt - 1e-9)))
        samples = self._samples(u, n)
        self.setup()
        self.counters = {"steps": n, "chunks": 0}
        times = np.arange(n + 1) * self.dt
        X = np.empty((n + 1, model.n_x))
        Y = np.empty((n + 1, self._outputs_fn.numel_out(0)))
        X[0] = x0
        start, cpu_start = time.perf_counter(), time.process_time()
        Y[0] = self._outputs(x0[None, :])[0]
        monitor = DivergenceMonitor(self, x0, Y[0])
        for s in range(0, n, self.chunk):
            k = min(self.chunk, n - s)
            Xc, Yc = self._advance(X[s].copy(), times[s : s + k + 1], samples[s : s + k])
            Xc = np.asarray(Xc, dtype=float).reshape(k, model.n_x)
            if Yc is None:
                finite = np.all(np.isfinite(Xc), axis=1)
                m = k if finite.all() else int(np.argmin(finite))
                Yc = np.full((k, Y.shape[1]), np.nan)
                if m:
                    Yc[:m] = self._outputs(Xc[:m])
            X[s + 1 : s + k + 1] = Xc
            Y[s + 1 : s + k + 1] = Yc
            self.counters["chunks"] += 1
            monitor.check(
                times[s + 1 : s + k + 1], X[s : s + k + 1], Y[s + 1 : s + k + 1], samples[s : s + k]
            )
        applied = np.vstack([samples, samples[-1:]])
        if self.u_function is not None:
            applied = (
                applied
                + np.asarray(self.u_function.map(n + 1)(times[None, :]), dtype=float)
                .reshape(model.n_u, -1)
                .T
            )
        wall, cpu = time.perf_counter() - start, time.process_time() - cpu_start
        traj = self._trajectory(times, X, Y, applied, wall)
        traj.meta["cpu_time_s"] = cpu
        return traj

    # -- hooks ------------------------------------------------------------------------
    def _setup(self) -> None:
        """Build and compile what the method needs (called once)."""

    def _advance(
        self, x0: np.ndarray, times: np.ndarray, U: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """States after each of ``len(U)`` steps from ``x0`` at ``times[0]``; outputs or None."""
        out = np.empty((U.shape[0], x0.size))
        x = x0
        for i in range(U.shape[0]):
            x = self._step(x, float(times[i]), U[i])
            out[i] = x
            if not np.all(np.isfinite(x)):
                out[i + 1 :] = np.nan
                break
        return out, None

    def _step(self, x: np.ndarray, t: float, u: np.ndarray) -> np.ndarray:
        """One step of length ``self.dt`` from ``(t, x)`` with held torque ``u``."""
        raise NotImplementedError(f"{type(self).__name__} implements neither _step nor _advance")

    def _outputs(self, X: np.ndarray) -> np.ndarray:
        """Outputs y for states X (rows), by one mapped evaluation."""
        Y = self._outputs_fn.map(X.shape[0])(X.T)
        return np.asarray(Y, dtype=float).reshape(-1, X.shape[0]).T

    # -- helpers ----------------------------------------------------------------------
    def _samples(self, u, n: int) -> np.ndarray:
        n_u = self.model.n_u
        if u is None:
            return np.zeros((n, n_u))
        arr = np.asarray(u, dtype=float)
        if arr.shape == (n_u,):
            arr = np.tile(arr, (n, 1))
        if arr.shape != (n, n_u):
            raise SpecError(
                f"torque samples have shape {arr.shape}; expected ({n}, {n_u}) "
                f"(one row per step of {self.dt:g} s) or ({n_u},)",
                key="u",
            )
        if not np.all(np.isfinite(arr)):
            raise SpecError("torque samples contain non-finite values", key="u")
        return arr

    def jacobian_radius(self, x: np.ndarray, u: np.ndarray | None = None) -> float:
        """Largest eigenvalue magnitude of ``df/dx`` at ``x`` (rad/s; free joints, current torque).

        ``Model.omega_max`` is the highest frequency of the linearisation at the build
        configuration (free joints, about 330 Hz for the three-link arm with two
        modes per link, against 189 Hz with locked joints); the Jacobian at the
        current state can differ, so stability advice uses the larger.
        """
        if not np.all(np.isfinite(x)):
            return math.nan
        if not hasattr(self, "_jac_fn"):
            self._jac_fn = try_expand(jacobian_function(self.model))
        u = np.zeros(self.model.n_u) if u is None else u
        return float(np.max(np.abs(np.linalg.eigvals(np.asarray(self._jac_fn(x, u), dtype=float)))))

    def stability_advice(self, states: tuple[np.ndarray, ...] = ()) -> str:
        """The stable step or integrator, from ``omega_max`` and the Jacobian at ``states``."""
        w_model = float(self.model.omega_max)
        radii = [r for r in (self.jacobian_radius(x) for x in states) if math.isfinite(r)]
        w = max([w_model, *radii])
        facts = (
            "The model's highest natural frequency (linearised, free joints) is omega_max = "
            f"{w_model:.4g} rad/s ({w_model / (2 * math.pi):.4g} Hz), "
            f"omega_max*dt = {w_model * self.dt:.3g}"
        )
        if radii:
            facts += (
                "; at the failing state the Jacobian df/dx (free joints) reaches |lambda| = "
                f"{max(radii):.4g} rad/s ({max(radii) / (2 * math.pi):.4g} Hz), "
                f"|lambda|*dt = {max(radii) * self.dt:.3g}"
            )
        facts += "."
        if math.isfinite(self.stability_limit) and w > 0:
            stable = 0.9 * self.stability_limit / w
            if w * self.dt > self.stability_limit:
                return (
                    f"{facts} {self.name} is stable only for omega*dt < {self.stability_limit:g}: "
                    f"use dt <= {stable:.3g} s, or an implicit integrator ('idas', 'cvodes', or "
                    "'scipy' with method 'Radau' or 'BDF')."
                )
            return (
                f"{facts} That is inside {self.name}'s limit omega*dt < {self.stability_limit:g}; "
                f"try dt <= {0.5 * stable:.3g} s or an implicit integrator ('idas', 'cvodes')."
            )
        return (
            f"{facts} Try tighter tolerances (rtol, atol) or a smaller dt, and check the model and "
            "initial state."
        )

    def _trajectory(self, times, X, Y, applied, wall) -> Trajectory:
        model = self.model
        energies = {"E_kin": Y[:, 0], "E_el": Y[:, 1], "E_grav": Y[:, 2]}
        energies["E_total"] = Y[:, 0] + Y[:, 1] + Y[:, 2]
        simulated = float(times[-1] - times[0])
        meta = {
            **self.settings(),
            "model": model.name,
            "fidelity": str(model.fidelity),
            "omega_max_rad_s": float(model.omega_max),
            "omega_max_dt": float(model.omega_max) * self.dt,
            "n_steps": int(times.size - 1),
            "wall_time_s": wall,
            "setup_time_s": self.setup_seconds,
            "realtime_factor": simulated / wall if wall > 0 else math.inf,
            "counters": dict(self.counters),
            "status": "ok",
        }
        return Trajectory(
            time=times,
            states=X,
            inputs=applied,
            coordinate_names=tuple(model.coordinate_names),
            energies=energies,
            tip=Y[:, 3:5],
            deflections=Y[:, 5:],
            meta=meta,
        )
