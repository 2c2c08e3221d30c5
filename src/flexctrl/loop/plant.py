"""The nonlinear arm stepped one controller sample at a time, for loops of one's own.

::

    ctrl = fc.design(model, op, fc.load_controller("lqr"))
    plant = fc.Plant(model, x0, sample_time=ctrl.sample_time, measurements=ctrl.sensors)
    ctrl.set_reference(move)
    ctrl.reset()
    y = plant.output()
    for k in range(400):
        u = ctrl.step(plant.time, y)      # torques, N m
        y = plant.step(u)                 # held for one sample; the next measurement
    plant.trajectory().plot(folder)       # the Trajectory every run gives

:meth:`Plant.step` is the closed loop's plant step (:mod:`flexctrl.loop.plant_step`): one
compiled call advances the state by RK4 steps of ``dt`` with the torque held over the
sample, clipped to the model's torque limits; the sensors are one compiled output map, with
Gaussian noise at their levels from a seeded generator.  With the same model, controller,
plant step and initial state, such a loop runs the arithmetic :func:`flexctrl.closed_loop`
runs (a linear controller's products in CasADi there and in NumPy here can differ in the
last digits).
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

import numpy as np

from flexctrl.errors import SimulationError, SpecError
from flexctrl.linear import Sensors, state_names, torque_limits
from flexctrl.loop.mismatch import plant_sensors
from flexctrl.loop.plant_step import advance_function
from flexctrl.loop.sampled import trajectory_from_states
from flexctrl.sim.bound import BoundFunction
from flexctrl.sim.rk4 import RK4_STABILITY_LIMIT, rk4_step
from flexctrl.sim.trajectory import Trajectory

#: Default ``omega_max * dt`` of the plant's RK4 step (here and in :func:`flexctrl.closed_loop`).
#: RK4 keeps the fraction ``|R(iy)|^2 = 1 - y^6/72 + y^8/576`` of an undamped mode's energy per
#: step, ``y = omega dt`` (:mod:`flexctrl.sim.rk4`): 0.99979 at ``y = 0.5`` but 0.52 at 2.05, so a
#: step chosen only for stability (``y`` up to 2.5) damps the fastest modes numerically and moves
#: the residual vibration; at 0.5 the residual agrees with the scenes' 0.5 ms step.
ACCURATE_OMEGA_DT = 0.5

#: Which sensor kind gives a measurement name.
_KIND_OF = (
    (r"q\d+", "joints"),
    (r"dq\d+", "joint_rates"),
    (r"kappa\d+", "strain"),
    (r"tip_[xy]", "tip"),
    (r"tip_a[xy]", "tip_acc"),
    (r"w\d+", "deflection"),
)


def accurate_plant_step(model, sample_time: float) -> float:
    """The largest whole fraction of ``sample_time`` (s) with ``omega_max * dt`` accurate, s.

    ``omega_max * dt <=`` :data:`ACCURATE_OMEGA_DT` on ``model``'s fastest mode (RK4 keeps
    0.99979 of an undamped mode's energy per step there).
    """
    return rk4_step(model.omega_max, sample_time, ACCURATE_OMEGA_DT / RK4_STABILITY_LIMIT)


def _rng(noise) -> np.random.Generator | None:
    if noise is None or isinstance(noise, np.random.Generator):
        return noise
    if isinstance(noise, bool) or not isinstance(noise, (int, np.integer)):
        raise SpecError(
            f"value {noise!r} is not allowed; allowed: None (exact measurements), a seed "
            "(int) or a numpy.random.Generator",
            key="noise",
        )
    return np.random.default_rng(int(noise))


def _kinds(model, names: Sequence[str]) -> tuple[str, ...]:
    """The sensor kinds that give ``names`` (``"state"`` for the state names)."""
    if tuple(names) == tuple(state_names(model)):
        return ("state",)
    kinds = []
    for name in names:
        kind = next((k for pattern, k in _KIND_OF if re.fullmatch(pattern, str(name))), None)
        if kind is None:
            raise SpecError(
                f"value {name!r} is not a measurement of this model; allowed: the names a "
                "controller measures (ctrl.measurement_names: q1, dq1, kappa1, tip_x, tip_ax, "
                f"w1, ...) or the state names ({', '.join(state_names(model))})",
                key="measurements",
            )
        if kind not in kinds:
            kinds.append(kind)
    return tuple(kinds)


def plant_measurements(model, measurements, q_joints) -> Sensors:
    """The sensors of a :class:`Plant`: from names, or a controller's sensors carried over.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The plant.
    measurements : Sensors, sequence of str or None
        A controller's :class:`~flexctrl.linear.Sensors` (``ctrl.sensors``: its kinds built
        again on ``model``, its noise levels carried over), measurement names
        (``ctrl.measurement_names``; the default noise levels of
        :data:`flexctrl.spec.sensors.DEFAULT_NOISE`), or None for the full state.
    q_joints : array_like
        Joint angles (rad) the strain gauges' map is taken at (scheduled modes).

    Returns
    -------
    Sensors
    """
    if measurements is None:
        return Sensors.build(model, ("state",))
    if isinstance(measurements, Sensors):
        return plant_sensors(model, measurements, q_joints)
    if isinstance(measurements, str) or not isinstance(measurements, Sequence):
        raise SpecError(
            f"value of type {type(measurements).__name__} is not allowed; allowed: "
            "ctrl.sensors, ctrl.measurement_names or None (the state)",
            key="measurements",
        )
    built = Sensors.build(model, _kinds(model, measurements), q_joints=q_joints)
    if built.names != tuple(measurements):
        raise SpecError(
            f"value {list(measurements)!r} is not allowed; allowed: names in the order the "
            f"sensors give them, here {list(built.names)}",
            key="measurements",
        )
    return built


class Plant:
    """The nonlinear ``model`` stepped one sample at a time, for loops of one's own.

    ``y = plant.step(u)`` holds the torques ``u`` (N m, clipped to the joints' limits) over one
    sample and returns the next measurement; :meth:`output` is the measurement now. The step
    is the one :func:`flexctrl.closed_loop` compiles (RK4 at ``dt``), so an own loop of
    ``ctrl.step`` and ``plant.step`` runs what ``closed_loop`` runs.

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The arm.
    x0 : array_like
        Initial state ``(q, qd)`` (rad, modal coordinates, their rates), or the joint
        angles alone (rad: at rest, links undeformed).
    sample_time : float
        How long :meth:`step` holds a torque, s (a controller's ``ctrl.sample_time``).
    measurements : Sensors, sequence of str, optional
        What :meth:`step` and :meth:`output` return: ``ctrl.sensors`` (with the
        controller's noise levels), ``ctrl.measurement_names``, or None for the state.
    noise : int or numpy.random.Generator, optional
        Seed (or generator) of Gaussian measurement noise at the sensors' levels; None
        measures exactly.
    dt : float, optional
        RK4 step, s, a whole fraction of ``sample_time``; default the one
        :func:`flexctrl.closed_loop` takes (:func:`accurate_plant_step`).
    saturate : bool
        Clip torques at the model's joint torque limits (N m).
    u0 : array_like, optional
        The torque held before the first step, N m (tip accelerometers feel it); default 0.
    compile : bool, optional
        Compile the step and the sensors to C (default: when a compiler is present).

    Attributes
    ----------
    sensors : Sensors
        The measurement model; ``sensors.names`` name :meth:`output`'s entries.
    limits : ndarray
        The torque limits applied, N m (``inf`` for none or without ``saturate``).
    """

    def __init__(
        self,
        model,
        x0,
        *,
        sample_time: float,
        measurements=None,
        noise: int | np.random.Generator | None = None,
        dt: float | None = None,
        saturate: bool = True,
        u0=None,
        compile: bool | None = None,
    ):
        self.model = model
        if isinstance(sample_time, bool) or not (
            isinstance(sample_time, (int, float)) and math.isfinite(sample_time) and sample_time > 0
        ):
            raise SpecError(
                f"value {sample_time!r} is not allowed; allowed: a time > 0 (s)",
                key="sample_time",
            )
        self.sample_time = float(sample_time)
        self.dt = accurate_plant_step(model, self.sample_time) if dt is None else float(dt)
        self.substeps = int(round(self.sample_time / self.dt))
        if self.substeps < 1 or abs(self.substeps * self.dt - self.sample_time) > 1e-9 * (
            self.sample_time
        ):
            raise SpecError(
                f"value {dt!r} does not divide the sample time {self.sample_time:g} s; "
                "allowed: sample_time/dt a whole number",
                key="dt",
            )
        x = self._initial(x0)
        limits = torque_limits(model)
        self.limits = limits if saturate else np.full(model.n_u, np.inf)
        self._rng = _rng(noise)
        advance, self.compiled = advance_function(model, self.substeps, compile)
        self._advance = BoundFunction(advance)
        self._use(plant_measurements(model, measurements, x[: model.n_u]))
        self._x0, self._u0 = x, self._torque(np.zeros(model.n_u) if u0 is None else u0, "u0")
        self.reset()

    @classmethod
    def for_controller(
        cls,
        model,
        controller,
        x0,
        *,
        noise: int | np.random.Generator | None = None,
        dt: float | None = None,
        compile: bool | None = None,
    ) -> Plant:
        """The plant ``controller`` runs on: its sample time, sensors and noise levels.

        The sensors are the controller's own when ``model`` is its design model (the
        ones :func:`flexctrl.closed_loop` reads), else its sensor kinds built on ``model``
        with its noise levels; torques saturate at ``model``'s limits and the torque held
        before the first step is the controller's ``u_previous`` (after :meth:`reset
        <flexctrl.control.controller.Controller.reset>`: its operating point's).

        Parameters
        ----------
        model : flexctrl.dynamics.model.Model
            The arm controlled (the design model or another payload or fidelity).
        controller : flexctrl.control.controller.Controller
            From :func:`flexctrl.design`.
        x0, noise, dt, compile
            As for :class:`Plant`.

        Returns
        -------
        Plant
        """
        plant = cls(
            model,
            x0,
            sample_time=controller.sample_time,
            noise=noise,
            dt=dt,
            u0=controller.u_previous,
            compile=compile,
        )
        if getattr(controller, "design_model", None) is model:
            plant._use(controller.sensors)
        else:
            plant._use(plant_sensors(model, controller.sensors, tuple(controller.op.joints)))
        return plant

    def _use(self, sensors: Sensors) -> None:
        """Measure with ``sensors`` (built on this plant's model)."""
        self.sensors = sensors
        self._outputs = BoundFunction(sensors.function)

    def _initial(self, x0) -> np.ndarray:
        model = self.model
        x = np.asarray(x0, dtype=float).ravel()
        if x.size == model.n_u:
            x = np.r_[x, np.zeros(model.n_x - model.n_u)]
        if x.size != model.n_x or not np.all(np.isfinite(x)):
            raise SpecError(
                f"value {np.asarray(x0).tolist()!r} is not allowed; allowed: {model.n_x} finite "
                f"values (q, qd) or {model.n_u} joint angles (rad)",
                key="x0",
            )
        return x

    def _torque(self, u, key: str = "u") -> np.ndarray:
        u = np.asarray(u, dtype=float).ravel()
        if u.size != self.model.n_u or not np.all(np.isfinite(u)):
            raise SpecError(
                f"value {np.asarray(u).tolist()!r} is not allowed; allowed: "
                f"{self.model.n_u} finite torques (N m), one per joint",
                key=key,
            )
        return u

    def reset(self, x0=None) -> None:
        """Start again at ``x0`` (default: the initial state given), time 0, no record."""
        self._x = self._initial(x0) if x0 is not None else self._x0.copy()
        self._u = self._u0.copy()
        self._k = 0
        self._blocks: list[np.ndarray] = [self._x[None, :]]
        self._torques: list[np.ndarray] = []

    @property
    def state(self) -> np.ndarray:
        """The state now, ``(q, qd)`` (rad, modal coordinates, their rates); a copy."""
        return self._x.copy()

    @property
    def time(self) -> float:
        """The time now, s (samples stepped times the sample time)."""
        return self._k * self.sample_time

    @property
    def measurement_names(self) -> tuple[str, ...]:
        """The names of :meth:`output`'s entries."""
        return self.sensors.names

    def output(self) -> np.ndarray:
        """The measurement now: the sensors at the state and the torque held, plus noise.

        Every call draws new noise (when the plant has a generator).
        """
        y = self._outputs(self._x, self._u)[0].ravel()
        return self.sensors.with_noise(y, self._rng)

    def step(self, u) -> np.ndarray:
        """Hold ``u`` (clipped to the torque limits) for one sample; the next measurement.

        Parameters
        ----------
        u : array_like
            One torque per joint, N m.

        Returns
        -------
        ndarray
            :meth:`output` at the end of the sample.

        Raises
        ------
        SpecError
            For a torque of the wrong length or not finite (named under the key ``u``).
        SimulationError
            When the state stops being finite (the step stays unrecorded).
        """
        u = np.clip(self._torque(u), -self.limits, self.limits)
        block = self._advance(self._x, u, self.dt)[0]
        if not np.all(np.isfinite(block)):
            raise SimulationError(
                f"the plant state is not finite at t = {self.time + self.sample_time:.4g} s "
                f"(torque {u.tolist()} N m, RK4 step {self.dt:g} s): the loop diverged"
            )
        self._x, self._u = block[-1].copy(), u
        self._blocks.append(block)
        self._torques.append(u)
        self._k += 1
        return self.output()

    def trajectory(self) -> Trajectory:
        """The run so far at the RK4 step: states, held torques (N m), tip, deflections.

        The :class:`~flexctrl.sim.trajectory.Trajectory` every run gives (``plot``,
        ``save``, ``to_pandas``).
        """
        X = np.vstack(self._blocks)
        per = self.substeps
        U = np.empty((X.shape[0], self.model.n_u))
        for k, u in enumerate(self._torques):
            U[k * per : (k + 1) * per] = u
        U[-1] = self._u
        t = np.arange(X.shape[0]) * self.dt
        meta = {
            "integrator": "rk4",
            "dt": self.dt,
            "sample_time": self.sample_time,
            "compiled": self.compiled,
            "loop": "plant",
        }
        return trajectory_from_states(self.model, t, X, U, meta)

    def __repr__(self) -> str:
        return (
            f"Plant({self.model.name!r}, t={self.time:g} s, sample_time={self.sample_time:g} s, "
            f"dt={self.dt:g} s, measures={list(self.sensors.names)})"
        )


__all__ = ["Plant", "accurate_plant_step", "plant_measurements"]
