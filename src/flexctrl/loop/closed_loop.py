"""The closed loop from Python: a designed controller, a move, a plant; one call, one result."""

from __future__ import annotations

import math

import numpy as np

from flexctrl.control.payload.grid import model_with_payload
from flexctrl.control.reference_trajectory import reference_from_move
from flexctrl.errors import SpecError, keyword_checked
from flexctrl.loop.mismatch import plant_sensors
from flexctrl.loop.monitors import divergence_monitor
from flexctrl.loop.plant import accurate_plant_step
from flexctrl.loop.result import ClosedLoopResult, tip_at_rest
from flexctrl.loop.run_summary import judge_run, run_summary
from flexctrl.loop.sampled import simulate_closed_loop
from flexctrl.loop.verdict import linear_closed_loop_radius
from flexctrl.spec.closed_loop_scene import MetricSettings
from flexctrl.spec.reference import JointReference, JointSequence, Move, MoveSequence


@keyword_checked
def closed_loop(
    model,
    controller,
    reference,
    duration: float,
    *,
    plant=None,
    dt: float | None = None,
    noise: int | np.random.Generator | None = None,
    x0=None,
    metrics: MetricSettings | None = None,
    on_divergence: str = "raise",
    compile: bool | None = None,
    payload_changes=(),
) -> ClosedLoopResult:
    """Run ``controller`` on ``plant`` (default ``model``) along ``reference`` for ``duration`` s.

    The controller tracks the reference built on ``model`` (its design model) at its sample
    time; the plant advances by RK4 steps of ``dt`` between samples (:mod:`flexctrl.loop.sampled`).

    Parameters
    ----------
    model : flexctrl.dynamics.model.Model
        The model the controller was designed on.
    controller : flexctrl.control.controller.Controller
        From :func:`flexctrl.design`; reset and given the reference.
    reference : Move, MoveSequence or JointReference
        The joint path (rad, s); a :class:`~flexctrl.spec.reference.MoveSequence` for moves one
        after the other (out and back).
    duration : float
        Simulated time, s.
    plant : Model, optional
        The arm controlled, e.g. another payload or fidelity; default ``model``.
    dt : float, optional
        Plant step, s, a whole fraction of the sample time; default the largest with
        ``omega_max * dt <=`` :data:`ACCURATE_OMEGA_DT` on the plant.
    noise : int or numpy.random.Generator, optional
        Seeded measurement noise at the controller's sensor levels; None measures exactly.
    x0 : array_like, optional
        Initial plant state ``(q, qd)`` (rad, m, rad/s); default at rest at the start.
    metrics : MetricSettings, optional
        How the run is judged (residual window, bands, divergence bounds).  The run
        diverges when a link's tip deflection exceeds its bound (by default the larger of
        0.1 of its length and four times the static deflection ``tau L^2 / (2 EI)`` of its
        joint's torque limit, so light arms keep room for their ordinary bending; a set
        ``divergence_deflection`` makes it that fraction of the length), or a joint leaves
        its move's range by more than ``divergence_angle`` (default 90 deg).
    on_divergence : {"raise", "record"}
        A diverging run raises :class:`~flexctrl.errors.SimulationError`, or stops and
        records ``stable = 0`` with ``divergence_time`` (s); its residual metrics and
        ``settling_time`` are then NaN, the reason in ``summary["metric_notes"]``.
    compile : bool, optional
        Compile the plant's step to C (default: when a compiler is present).
    payload_changes : sequence of (float, float)
        ``(time s, mass kg)``: the plant's payload becomes ``mass`` from the first controller
        sample at or after ``time`` (a grasp or release; give times when the arm is at rest).
        The plant is rebuilt with that payload and the run continues from the same state.
        The payload metrics judge the estimate against the payload at each sample.

    Returns
    -------
    ClosedLoopResult
        ``metrics`` (SI units), ``trajectory``, ``summary``, ``plot()``, ``save(dir)`` ...

    Examples
    --------
    >>> import numpy as np, flexctrl as fc
    >>> model = fc.load_model("subedi3link", payload=2.0, fidelity="rigid", gravity=[0.0, 0.0])
    >>> op = fc.equilibrium(model, np.radians([30, 0, 0]))
    >>> pd = fc.design(model, op, fc.load_controller("pd"))
    >>> move = fc.Move(start=np.radians([0, 0, 0]), target=np.radians([30, 0, 0]), time=1.5)
    >>> res = fc.closed_loop(model, pd, move, duration=4.0)
    >>> bool(res.metrics["stable"]), res.metrics["tip_residual_rms"] < 1e-3
    (True, True)
    """
    move = _checked_move(model, controller, reference, duration, on_divergence)
    path, plant = move.joint_reference(), model if plant is None else plant
    judge = MetricSettings() if metrics is None else metrics
    _track(controller, model, move)
    sensors = _plant_sensors(model, plant, controller)
    changes = _payload_changes(plant, controller, payload_changes)
    trajectory, _ = simulate_closed_loop(
        plant,
        controller,
        _initial_state(plant, path, x0),
        float(duration),
        _plant_step(plant, controller, dt),
        sensors=sensors,
        rng=_noise(noise),
        compile=compile,
        monitor=_monitor(plant, path, judge),
        stop_on_divergence=on_divergence == "record",
        plant_changes=changes,
    )
    truth = _payload_truth(plant, changes)
    if changes:  # judged on the plant the run ends on
        plant, sensors = changes[-1][1], changes[-1][2]
    return _result(
        trajectory, model, plant, controller, move, judge, float(duration), sensors, truth
    )


def _payload_changes(plant, controller, changes) -> list:
    """``(time, plant, sensors)`` of every payload change, the plants rebuilt carrying it."""
    out = []
    for when, mass in changes:
        for key, value, unit in (("time", when, "s"), ("mass", mass, "kg")):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
                raise SpecError(
                    f"value {value!r} is not allowed; allowed: a number >= 0 ({unit})",
                    key=f"payload_changes.{key}",
                )
        new = model_with_payload(plant, float(mass))
        out.append((float(when), new, plant_sensors(new, controller.sensors, controller.op.joints)))
    return sorted(out, key=lambda change: change[0])


def _payload_truth(plant, changes):
    """The plant's payload (kg), or a function of time (s) when it changes."""
    if not changes:
        return plant.spec.payload.mass
    times = np.array([c[0] for c in changes])
    masses = np.array([plant.spec.payload.mass] + [c[1].spec.payload.mass for c in changes])
    return lambda t: masses[np.searchsorted(times, np.asarray(t) + 1e-9, side="right")]


def _track(controller, model, move: Move | MoveSequence) -> None:
    """Reset ``controller`` and give it ``move``'s reference built on its design model."""
    controller.set_reference(reference_from_move(model, move))
    controller.reset()


def _plant_sensors(model, plant, controller):
    """The controller's sensors as they read the plant (built on it when it is another model)."""
    if plant is model:
        return controller.sensors
    return plant_sensors(plant, controller.sensors, tuple(controller.op.joints))


def _monitor(plant, path: JointReference | JointSequence, judge: MetricSettings):
    return divergence_monitor(
        plant,
        plant.spec,
        path.q_start,
        path.q_target,
        judge.divergence_deflection,
        judge.divergence_angle,
    )


def _checked_move(
    model, controller, reference, duration, on_divergence: str
) -> Move | MoveSequence:
    """The reference as a :class:`Move`, once the arguments are checked."""
    _check_arguments(controller, on_divergence)
    move = _as_move(reference)
    _check_path(model, move.joint_reference(), duration)
    return move


def check_on_divergence(on_divergence: str) -> None:
    """:class:`SpecError` unless ``on_divergence`` is ``"raise"`` or ``"record"``."""
    if on_divergence not in ("raise", "record"):
        raise SpecError(
            f"value {on_divergence!r} is not allowed; allowed: 'raise', 'record'",
            key="on_divergence",
        )


def _check_arguments(controller, on_divergence: str) -> None:
    check_on_divergence(on_divergence)
    if not (hasattr(controller, "step") and hasattr(controller, "sensors")):
        raise SpecError(
            f"value of type {type(controller).__name__} is not a controller; allowed: a "
            "controller from flexctrl.design(model, op, settings)",
            key="controller",
        )


def _check_path(model, path: JointReference | JointSequence, duration) -> None:
    """The path has one angle per joint and the run outlasts it."""
    if len(path.q_target) != model.n_u:
        raise SpecError(
            f"the move has {len(path.q_target)} joint angles; expected {model.n_u} (one per joint)",
            key="reference",
        )
    if (
        isinstance(duration, bool)
        or not isinstance(duration, (int, float))
        or not math.isfinite(duration)
        or duration <= path.t_arrive
    ):
        raise SpecError(
            f"value {duration!r} is not allowed; allowed: a duration (s) longer than the move "
            f"({path.t_arrive:g} s)",
            key="duration",
        )


def _plant_step(plant, controller, dt: float | None) -> float:
    """``dt``, or the largest whole fraction of the sample time with ``omega_max * dt`` accurate."""
    if dt is not None:
        return float(dt)
    return accurate_plant_step(plant, controller.sample_time)


def _initial_state(plant, path: JointReference | JointSequence, x0) -> np.ndarray:
    """``x0``, or the plant at rest at the path's start with undeformed links."""
    if x0 is None:
        x0 = np.zeros(plant.n_x)
        x0[: plant.n_u] = path.q_start
    x0 = np.asarray(x0, dtype=float)
    if x0.shape != (plant.n_x,) or not np.all(np.isfinite(x0)):
        raise SpecError(
            f"has shape {x0.shape}; expected ({plant.n_x},) finite values (q, qd)", key="x0"
        )
    return x0


def _noise(noise) -> np.random.Generator | None:
    if isinstance(noise, np.random.Generator) or noise is None:
        return noise
    return np.random.default_rng(noise)


def _result(
    trajectory, model, plant, controller, move: Move | MoveSequence, judge, duration, sensors, truth
) -> ClosedLoopResult:
    """The run judged (metrics, linear verdict) and described (summary)."""
    path = move.joint_reference()
    tip_target = tip_at_rest(plant, path.q_target)
    values = judge_run(
        trajectory,
        controller,
        path,
        judge,
        tip_target=tip_target,
        torque_limits=[getattr(j, "torque_limit", math.inf) for j in plant.spec.joints],
        radius=linear_closed_loop_radius(plant, controller, path.q_target, sensors),
        true_payload=truth,
    )
    summary = run_summary(
        trajectory,
        values,
        controller,
        plant=plant,
        payload=plant.spec.payload.mass,
        design={
            "fidelity": str(model.fidelity),
            "payload_kg": model.spec.payload.mass,
            "configuration_deg": np.degrees(controller.op.joints).tolist(),
        },
        path=path,
        deflection=move.deflection,
        tip_target=tip_target,
        judge=judge,
    )
    return ClosedLoopResult(
        trajectory=trajectory,
        metrics=values,
        summary=summary,
        model=plant,
        controller=controller,
        reference=path,
        payload_estimate=_payload_trace(controller),
    )


def _payload_trace(controller):
    """A payload-aware controller's estimate trace (:class:`ClosedLoopResult`), else None."""
    trace = getattr(controller, "payload_trace", None)
    return None if trace is None else trace()


def _as_move(reference) -> Move | MoveSequence:
    if isinstance(reference, (Move, MoveSequence)):
        return reference
    if isinstance(reference, JointReference):
        return Move(
            reference.q_start,
            reference.q_target,
            reference.move_time,
            reference.profile,
            reference.t_start,
        )
    raise SpecError(
        f"value of type {type(reference).__name__} is not a reference; allowed: "
        "flexctrl.Move(start=, target=, time=) (rad, s) or a JointReference",
        key="reference",
    )
