"""The one small protocol every controller follows, and its bookkeeping.

A closed loop needs only this::

    ctrl = design(model, op, settings)          # flexctrl.control.design
    ctrl.reset()
    for k in range(n_samples):                  # every ctrl.sample_time seconds
        y = ctrl.sensors.measure(x, u, rng)     # the measurement vector ctrl expects
        u = ctrl.step(t, y)                     # joint torques (N m), held until the next sample
    ctrl.stats.summary()                        # wall time per step, status counts, fallbacks

A controller regulates to its :attr:`Controller.reference`: by default its operating
point (:class:`~flexctrl.control.reference_trajectory.HoldReference`), or a moving reference
given by :meth:`Controller.set_reference` (a
:class:`~flexctrl.control.reference_trajectory.ReferenceTrajectory`: joint path, reference state,
feed-forward torque), which every controller reads at its sample times.

``step`` is a template method (like scipy's ``OdeSolver.step``): the base class
checks the measurement, times the call, clips to the torque limits and records;
subclasses implement ``_step``.  ``u`` passed to ``sensors.measure`` is the torque
held during the sample that just ended (tip accelerometers feel it).

The bad-measurement contract lives in :meth:`Controller.step` alone: a measurement of the
wrong length, or with a non-finite entry, raises
:class:`~flexctrl.errors.MeasurementError` (naming the channel, its value and the sample
time) before the controller changes any of its state, so the next valid measurement gives
the torque it would have given had the bad one never come.  With ``on_bad_measurement =
"hold"`` in the settings a non-finite measurement instead skips the correction: the base
class calls the subclass's ``_hold(t)`` (the estimator predicts with the torque applied and
the law acts on the prediction; PD holds its torque) and counts the sample in
``stats.status["held"]``.
"""

from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from collections import Counter
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from flexctrl.control.reference_trajectory import HoldReference, reference_from_move
from flexctrl.errors import MeasurementError, SpecError
from flexctrl.linear import OperatingPoint, Sensors
from flexctrl.spec.reference import Move


@dataclass(frozen=True, eq=False)
class SampledLaw:
    """A controller's law as one CasADi map, to run many samples in one call.

    The compiled closed loop (:mod:`flexctrl.loop.compiled`) chains it with the plant step.

    Per sample ``k``: ``(xi_k, u_k) = function(xi_{k-1}, y_k, u_{k-1}, r_k)`` with ``xi`` the
    controller's memory, ``y`` the measurement, ``u_{k-1}`` the torque held during the
    sample that just ended (after clipping) and ``r_k`` the row ``k`` of
    ``references(times)``; ``u_k`` is before clipping (the loop clips when the controller
    saturates).  The same arithmetic as the controller's ``_step``.

    Attributes
    ----------
    function : casadi.Function
        ``(xi, y, u_prev, r) -> (xi_next, u)``.
    memory : ndarray
        ``xi`` now (after the steps taken so far).
    references : callable
        ``references(times) -> (T, n_r)`` array: the reference rows at sample times (s) from
        now on.
    restore : callable
        ``restore(xi)``: put the controller into the state of memory ``xi`` (after a compiled
        run).
    status : str
        What each step records in :attr:`ControllerStats.status`.
    """

    function: Any
    memory: np.ndarray
    references: Any
    restore: Any
    status: str = "ok"


@dataclass
class ControllerStats:
    """What a controller did since its last :meth:`Controller.reset`.

    Attributes
    ----------
    step_times : list of float
        Wall time of every ``step`` call, s.
    status : collections.Counter
        Count per status string (``"ok"``, ``"solved"``, ``"fallback_shift"``, ...).
    fallbacks : list of (float, str, str)
        ``(t, reason, what was used)`` for every step whose optimiser did not deliver.
    saturated : int
        Steps in which at least one torque was clipped to its limit.
    clipped_max : float
        Largest amount clipped from a torque, N m (an optimiser that respects the
        limits leaves only its tolerance here).
    iterations : list of int
        Solver iterations per step (optimising controllers).
    slack_max : float
        Largest soft-constraint violation seen (m), optimising controllers.
    notes : dict
        Controller-specific figures added to the summary (e.g. the MPC's planned arrival).
    """

    step_times: list[float] = field(default_factory=list)
    status: Counter = field(default_factory=Counter)
    fallbacks: list[tuple[float, str, str]] = field(default_factory=list)
    saturated: int = 0
    clipped_max: float = 0.0
    iterations: list[int] = field(default_factory=list)
    slack_max: float = 0.0
    notes: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """Step count, median / p95 / max wall time (ms), status counts, fallbacks, saturation."""
        times = np.asarray(self.step_times) * 1e3
        pct = (lambda q: float(np.percentile(times, q))) if times.size else (lambda q: math.nan)
        return {
            "steps": int(times.size),
            "median_ms": pct(50),
            "p95_ms": pct(95),
            "max_ms": float(times.max()) if times.size else math.nan,
            "status": dict(self.status),
            "fallbacks": len(self.fallbacks),
            "saturated": self.saturated,
            "clipped_max": self.clipped_max,
            "median_iterations": float(np.median(self.iterations)) if self.iterations else math.nan,
            "slack_max": self.slack_max,
            **self.notes,
        }


class Controller(ABC):
    """Base class: ``reset()``, ``step(t, measurement) -> torques``, ``sample_time``, ``stats``.

    Parameters
    ----------
    settings
        The controller's settings dataclass.
    op : OperatingPoint
        The target equilibrium the controller regulates to.
    sensors : Sensors
        The measurement model: ``step`` expects ``sensors.names`` in this order.
    limits : ndarray
        Torque limits per joint, N m (``inf`` for none).
    saturate : bool
        Clip torques at ``limits``.
    design_model : Model, optional
        The model the controller was designed on; the closed loop builds the controller's
        reference (:meth:`set_reference`) on it.
    """

    kind: ClassVar[str] = ""
    #: What :func:`flexctrl.control.design` found fragile in the design model's sampled
    #: form (a :class:`~flexctrl.control.sampling_check.SamplingDiagnosis`), or None.
    design_diagnosis: Any = None

    def __init__(
        self,
        settings,
        op: OperatingPoint,
        sensors: Sensors,
        limits: np.ndarray,
        *,
        saturate: bool = True,
        design_model=None,
    ):
        self.settings = settings
        self.op = op
        self.sensors = sensors
        self.limits = np.asarray(limits, dtype=float)
        self.saturate = saturate
        self.n_u = self.limits.size
        #: The model the controller was designed on.
        self.design_model = design_model
        self.stats = ControllerStats()
        self.u_previous = np.array(op.u, dtype=float)
        self.reference = HoldReference(op)

    def set_reference(self, reference) -> None:
        """Track ``reference`` from now on.

        Parameters
        ----------
        reference : Move, ReferenceTrajectory or None
            A :class:`~flexctrl.spec.reference.Move` (joint angles in rad, times in s) is
            built into the reference :func:`flexctrl.closed_loop` gives the controller: its
            joint path, the quasi-static deflection along it and the feed-forward torque on
            the controller's :attr:`design_model`.  A
            :class:`~flexctrl.control.reference_trajectory.ReferenceTrajectory` must be built
            on the design model.  ``None`` restores regulation to the operating point.  The
            reference survives :meth:`reset`; call :meth:`reset` before a new run.

        Raises
        ------
        SpecError
            When the reference has another number of joints, or a move is given to a
            controller without a design model.
        """
        if isinstance(reference, Move):
            if self.design_model is None:
                raise SpecError(
                    "a Move needs the controller's design model to build its reference; "
                    "allowed: a controller from flexctrl.design, or a ReferenceTrajectory",
                    key="reference",
                )
            if len(reference.target) != self.n_u:
                raise SpecError(
                    f"the move has {len(reference.target)} joint angles; expected {self.n_u}",
                    key="reference",
                )
            reference = reference_from_move(self.design_model, reference)
        if reference is not None and len(reference.path.q_target) != self.n_u:
            raise SpecError(
                f"the reference has {len(reference.path.q_target)} joint angles; "
                f"expected {self.n_u}",
                key="reference",
            )
        self.reference = HoldReference(self.op) if reference is None else reference
        self._reference_changed()

    def _reference_changed(self) -> None:  # noqa: B027 (an optional hook, empty by design)
        """Subclass hook: the reference was replaced."""

    @property
    def sample_time(self) -> float:
        """Sample period, s: call :meth:`step` this often and hold the torque in between."""
        return float(self.settings.sample_time)

    @property
    def measurement_names(self) -> tuple[str, ...]:
        """Names of the entries of the measurement vector :meth:`step` expects."""
        return self.sensors.names

    def reset(self) -> None:
        """Forget everything since the design (estimates, warm starts, statistics)."""
        self.stats = ControllerStats()
        self.u_previous = np.array(self.op.u, dtype=float)
        self._reset()

    def step(self, t: float, measurement) -> np.ndarray:
        """Joint torques for the measurement taken at time ``t``.

        The controller regulates the arm to its :attr:`reference` at ``t``: the operating
        point it was designed for, or the path given by :meth:`set_reference` (joint angles,
        the quasi-static deflection along them, the feed-forward torque).  Checks the
        measurement, times the call, clips to the torque limits (when the controller
        saturates) and records; the subclass's ``_step`` computes the law.

        Parameters
        ----------
        t : float
            The time of the measurement, s.
        measurement : array_like
            The values named by :attr:`measurement_names`, in their units (rad, rad/s, 1/m,
            m, m/s^2).

        Returns
        -------
        ndarray
            One torque per joint, N m, to hold until the next sample.

        Raises
        ------
        MeasurementError
            When the measurement has the wrong number of entries, or a non-finite entry and
            the settings' ``on_bad_measurement`` is ``"raise"`` (the default), or is
            ``"hold"`` before any valid measurement.  The controller is left as it was.
        """
        start = time.perf_counter()
        y = self._checked_measurement(t, measurement)
        if y is None:
            held = self._hold(float(t))
            if held is None:
                raise MeasurementError(
                    f"cannot hold at t = {float(t):g} s: no valid measurement yet to predict "
                    "from; allowed: a first measurement with finite values",
                    t=float(t),
                )
            self.stats.status["held"] += 1
            u = np.asarray(held, dtype=float).ravel()
        else:
            u = np.asarray(self._step(float(t), y), dtype=float).ravel()
        if self.saturate:
            clipped = np.clip(u, -self.limits, self.limits)
            if np.any(clipped != u):
                self.stats.saturated += 1
                self.stats.clipped_max = max(
                    self.stats.clipped_max, float(np.max(np.abs(clipped - u)))
                )
            u = clipped
        self.u_previous = u
        self.stats.step_times.append(time.perf_counter() - start)
        return u.copy()

    @property
    def on_bad_measurement(self) -> str:
        """``"raise"`` or ``"hold"``: what :meth:`step` does with a non-finite measurement."""
        return str(getattr(self.settings, "on_bad_measurement", "raise"))

    def _checked_measurement(self, t: float, measurement) -> np.ndarray | None:
        """The measurement as a float vector, None to hold, or :class:`MeasurementError`."""
        y = np.asarray(measurement, dtype=float).ravel()
        names = self.sensors.names
        if y.size != self.sensors.n_y:
            raise MeasurementError(
                f"measurement at t = {float(t):g} s has {y.size} entries; expected "
                f"{self.sensors.n_y} ({', '.join(names)})",
                value=float(y.size),
                t=float(t),
            )
        finite = np.isfinite(y)
        if np.all(finite):
            return y
        i = int(np.argmin(finite))
        if self.on_bad_measurement == "hold":
            return None
        raise MeasurementError(
            f"measurement channel {names[i]!r} (entry {i}) is {float(y[i])} at t = {float(t):g} s; "
            "allowed: finite values (or on_bad_measurement = 'hold' in the settings to "
            "predict through such samples)",
            channel=names[i],
            value=float(y[i]),
            t=float(t),
        )

    def record(self, status: str) -> None:
        """Count ``status`` for this step."""
        self.stats.status[status] += 1

    def fallback(self, t: float, reason: str, used: str) -> None:
        """Record that the optimiser failed (``reason``) and ``used`` was applied instead."""
        self.stats.fallbacks.append((t, reason, used))
        self.stats.status[f"fallback_{used}"] += 1

    @abstractmethod
    def _step(self, t: float, y: np.ndarray) -> np.ndarray:
        """Torques for measurement ``y`` (before clipping)."""

    def _reset(self) -> None:  # noqa: B027 (an optional hook, empty by design)
        """Subclass part of :meth:`reset`."""

    def _hold(self, t: float) -> np.ndarray | None:
        """Torques for a sample whose measurement is skipped (``on_bad_measurement = "hold"``).

        Prediction only: the estimator advances its model with the torque applied
        (:attr:`u_previous`) without a correction, and the law acts on the prediction.
        None when there is nothing to predict from (no valid measurement since
        :meth:`reset`); :meth:`step` then raises.
        """
        raise NotImplementedError(
            f"{type(self).__name__} does not implement _hold; it cannot skip a measurement"
        )

    def sampled_law(self) -> SampledLaw | None:
        """The law as one CasADi map from the current state (:class:`SampledLaw`), or None.

        Called after at least one :meth:`step` (memories such as a Kalman filter's start
        from the first measurement).  Controllers that solve an optimisation per sample
        (MPC, NMPC) or interpolate gains (a schedule) give None: the loop steps them in Python.
        """
        return None

    def has_sampled_law(self) -> bool:
        """Whether :meth:`sampled_law` gives a law once the controller has stepped.

        Known before any step.

        Override it together with :meth:`sampled_law`: a controller that gives a law but
        says False here is only walked more slowly by the fidelity chooser, never wrongly.

        False here and for the controllers that solve an optimisation per sample: their loop
        steps in Python, so a run of theirs costs about the same on a linear plant as on the
        nonlinear one (the automatic-fidelity chooser uses this, :mod:`flexctrl.scenes.auto`).
        """
        return False

    def export_c(self, out, *, replay=None, qp_eps: float | None = None):
        """Write the designed controller as a self-contained C library into the folder ``out``.

        The library steps the same law as :meth:`step` (``flexctrl_step(c, k, y, u)`` every
        :attr:`sample_time`; measurements in the order and units of
        :attr:`measurement_names`, torques in N m), with a header, a ``Makefile`` for the
        system C compiler and a harness: ``make -C out check`` replays ``replay`` and
        compares the C torques with Python's (:mod:`flexctrl.control.cexport`).

        Parameters
        ----------
        out : str or path-like
            The folder to write (created; the files of an earlier export are overwritten).
        replay : flexctrl.control.cexport.Replay, optional
            Steps of this controller recorded in a closed loop
            (:class:`~flexctrl.control.cexport.StepRecorder`); without it ``make check`` has
            nothing to compare.
        qp_eps : float, optional
            The linear MPC's QP tolerance in C (absolute and relative); default 1/100 of the
            controller's OSQP ``eps_abs`` (1/1000 without warm starts).

        Returns
        -------
        flexctrl.control.cexport.Export
            The folder, the files written and the bound ``make check`` holds.

        Raises
        ------
        SpecError
            For a kind with no C export (allowed: an LQR/LQG without a gain schedule, a
            linear MPC), which this base method is.
        """
        if getattr(self.settings, "payload", None) is not None:
            raise SpecError(
                f"a payload-aware {self.kind} (a [payload] table) has no C export: its payload "
                "bank and grid run in Python; allowed: an LQR/LQG without a gain schedule or "
                "payload table, or a linear MPC",
                key="payload",
                source=getattr(self.settings, "source", None),
            )
        raise SpecError(
            f"value {self.kind or type(self).__name__!r} has no C export; allowed: an LQR/LQG "
            "without a gain schedule, or a linear MPC ('lqr', 'mpc')",
            key="kind",
            source=getattr(self.settings, "source", None),
        )

    def __repr__(self) -> str:
        names = list(self.sensors.names)
        return f"{type(self).__name__}(sample_time={self.sample_time:g} s, measures={names})"


__all__ = ["Controller", "ControllerStats", "SampledLaw"]
