"""The sampled-data closed loop: a nonlinear plant integrated finely, a controller at its own rate.

Per controller sample (period ``Ts = controller.sample_time``):

1. the *plant's* sensors measure the plant state (noise from the controller's
   sensor settings when the scene enables it; a real strain gauge reads the true
   curvature, so the measurement model is built on the plant, not on the design
   model);
2. ``u = controller.step(t, y)`` (clipped to the torque limits by the controller);
3. the plant advances ``Ts`` with ``u`` held (zero-order hold) by ``Ts/dt`` RK4 steps
   inside ONE compiled CasADi call that also returns the intermediate states, so
   the tip vibration is recorded at the plant rate.

Payload mismatch (plant carries one payload, the controller was designed for
another), a controller designed on a coarser model than the plant and one designed
(linearised) at another configuration than the target are scene settings.  The
controllers track the scene's reference (:mod:`flexctrl.control.reference`: a step
or a quintic from the initial joint angles to the target, with its quasi-static
deflection and feed-forward torque on the design model).

Instability is detected, never a silent NaN: after every controller sample the
plant state must be finite, its modal coordinates and rates within physical bounds
(:data:`MODAL_BOUND`, :data:`RATE_BOUND`), every link's tip deflection below the
scene's ``divergence_deflection`` (a fraction of the link's length: beyond it the
small-deflection model means nothing) and every joint within ``divergence_angle`` of
the range of its move.  A run that leaves these bounds stops there:
:func:`run_closed_loop_scene` raises :class:`~flexctrl.errors.SimulationError` naming
the time and the bound (``on_divergence="raise"``, ``flexctrl simulate``), or records it
(``"record"``, the study executor): metrics ``stable = 0`` and ``divergence_time``
(s), the other metrics over the run up to then (see :func:`run_closed_loop_scene`), so
a study row stays ``ok`` and a stability map is a map of the ``stable`` column.

A loop can also fail to converge without leaving those bounds: the linear loop is
unstable but torque saturation holds it in a limit cycle (e.g. an LQR designed for no
payload carrying 4 kg: all torques at their limits, the tip swinging 0.1-0.6 m for
the whole run).  So ``stable = 1`` also needs the largest tip error of the last
:data:`FINAL_WINDOW` s (``final_tip_error``, m) within the scene's ``stable_band``
(default 10 mm, ten times the settling band).  For state-feedback controllers
``closed_loop_radius`` is the linear verdict, computed independently of the run
(:func:`linear_closed_loop_radius`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from flexctrl.errors import FlexctrlError, SimulationError, SolverError, SpecError
from flexctrl.metrics import closed_loop_metrics
from flexctrl.sim.compile import compile_function
from flexctrl.sim.parametric import constants_as_parameters
from flexctrl.sim.rk4 import rk4_step_function
from flexctrl.sim.trajectory import Trajectory

#: Bounds beyond which the plant is declared diverged: |modal coordinate| (m), |rate| (rad/s or m/s).
MODAL_BOUND = 10.0
RATE_BOUND = 1e4
#: Length (s) of the end of a run whose largest tip error decides ``stable`` (with the scene's ``stable_band``).
FINAL_WINDOW = 1.0


def linear_closed_loop_radius(plant, controller, target_q) -> float | None:
    """Spectral radius of the *plant's* ZOH linearisation at the target closed with the controller's gain.

    ``max |eig(A_d - B_d K)|`` with ``A_d, B_d`` of the plant (its own payload) at the
    target equilibrium and ``K`` the controller's state-feedback gain there (LQR, gain-
    scheduled LQR, the unconstrained MPC), times the :func:`state_projection` when the
    plant is another assumed-modes rung than the design model: below 1 the target is locally asymptotically
    stable under the unsaturated law, an independent check of the simulated verdict.
    ``None`` for controllers without a full-state gain or of another state dimension.
    """
    import control

    from flexctrl.linear import Linearizer, discretize, equilibrium

    if not getattr(controller.sensors, "full_state", False):
        return None
    if controller.sensors.n_y == plant.n_x:
        P = np.eye(plant.n_x)
    else:
        try:
            P = state_projection(plant, controller.sensors.names)
        except SpecError:
            return None
    op = equilibrium(plant, np.asarray(target_q, dtype=float))
    if hasattr(controller, "gain"):
        K = controller.gain(P @ op.x)
    elif hasattr(controller, "K"):
        K = controller.K
    else:
        return None
    A, B, _C, _D = Linearizer(plant, ("joints",)).matrices(op)
    sysd = discretize(control.ss(A, B, np.eye(A.shape[0]), 0), controller.sample_time)
    Ad, Bd = np.asarray(sysd.A, dtype=float), np.asarray(sysd.B, dtype=float)
    return float(np.max(np.abs(np.linalg.eigvals(Ad - Bd @ np.asarray(K, dtype=float) @ P))))


#: Above this many plant steps per controller sample the step function is a CasADi ``mapaccum`` loop
#: (compiles in constant time) instead of an unrolled chain (faster, but its C code grows with the count).
UNROLL_LIMIT = 32


def plant_step_function(model, substeps: int, f: ca.Function | None = None, n_constants: int = 0) -> ca.Function:
    """``advance(x, u, h[, c]) -> (X)``: ``substeps`` RK4 steps of size ``h`` (s) with ``u`` held; X is (n_x, substeps).

    The steps are unrolled into one expression (compiled whole by :func:`advance_function`
    up to :data:`UNROLL_LIMIT` steps).  With ``f = fp(x, u, c)`` (the model's ``f`` with
    its constants as the input ``c`` of length ``n_constants``, from
    :func:`flexctrl.sim.parametric.constants_as_parameters`) the constants are an input
    too, and the Function's name depends only on the sizes: every configuration of one
    model shape then shares one compiled library.
    """
    x = ca.MX.sym("x", model.n_x)
    u = ca.MX.sym("u", model.n_u)
    h = ca.MX.sym("h")
    if f is None:
        step = rk4_step_function(model)
        advance = lambda xs, k: step(xs, k * h, u, h)[0]  # noqa: E731
        inputs, names, name = [x, u, h], ["x", "u", "h"], f"advance_{model.name}_{substeps}"
    else:
        c = ca.MX.sym("c", n_constants)

        def advance(xs, k):
            k1 = f(xs, u, c)
            k2 = f(xs + 0.5 * h * k1, u, c)
            k3 = f(xs + 0.5 * h * k2, u, c)
            k4 = f(xs + h * k3, u, c)
            return xs + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

        inputs, names, name = [x, u, h, c], ["x", "u", "h", "c"], f"advance_p_{model.n_x}_{model.n_u}_{n_constants}_{substeps}"
    states = []
    current = x
    for k in range(substeps):
        current = advance(current, k)
        states.append(current)
    return ca.Function(_name(name), inputs, [ca.horzcat(*states)], names, ["X"])


def _name(text: str) -> str:
    return re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9]", "_", text)).strip("_")


def advance_function(model, substeps: int, compile: bool | None = None) -> tuple[ca.Function, bool]:
    """The plant's ``advance(x, u, h) -> (X)`` over one controller sample, compiled; and whether it is.

    Up to :data:`UNROLL_LIMIT` steps: :func:`plant_step_function` compiled whole (the
    fastest per call).  Above (a fine plant step under a slow controller, e.g. ``amm:5``
    at 38 us under a 10 ms LQR: 260 steps): ONE compiled RK4 step, chained by a CasADi
    ``mapaccum`` loop in the virtual machine, so one library per model serves every
    step count and step size (compiling ``amm:5``'s step takes about 13 s here, the
    same as six unrolled steps).
    """
    if substeps <= UNROLL_LIMIT:
        fp, constants = constants_as_parameters(model.functions["f"])
        if constants.size == 0:  # f could not be rebuilt: one library per model
            compiled = compile_function(plant_step_function(model, substeps), enabled=compile)
            return compiled.function, compiled.compiled
        compiled = compile_function(plant_step_function(model, substeps, fp, constants.size), enabled=compile)
        x, u, h = ca.MX.sym("x", model.n_x), ca.MX.sym("u", model.n_u), ca.MX.sym("h")
        X = compiled.function(x, u, h, ca.DM(constants))
        return ca.Function(_name(f"advance_{model.name}_{substeps}"), [x, u, h], [X], ["x", "u", "h"], ["X"]), compiled.compiled
    step = rk4_step_function(model)
    xs, ts, us, hs = ca.MX.sym("x", model.n_x), ca.MX.sym("t"), ca.MX.sym("u", model.n_u), ca.MX.sym("h")
    single = ca.Function(_name(f"rk4x_{model.name}"), [xs, ts, us, hs], [step(xs, ts, us, hs)[0]],
                         ["x", "t", "u", "h"], ["x_next"])
    compiled = compile_function(single, enabled=compile)
    loop = compiled.function.mapaccum(substeps)
    x = ca.MX.sym("x", model.n_x)
    u = ca.MX.sym("u", model.n_u)
    h = ca.MX.sym("h")
    X = loop(x, h * ca.DM(np.arange(substeps, dtype=float)).T, ca.repmat(u, 1, substeps), ca.repmat(h, 1, substeps))
    return ca.Function(_name(f"advance_{model.name}_{substeps}"), [x, u, h], [X], ["x", "u", "h"], ["X"]), compiled.compiled


def _mapped(model, name: str, count: int, *args):
    return model.functions[name].map(count)(*args)


def trajectory_from_states(model, t: np.ndarray, X: np.ndarray, U: np.ndarray, meta: dict[str, Any]) -> Trajectory:
    """A :class:`Trajectory` with energies, tip and deflections evaluated by mapped CasADi calls."""
    count = t.size
    q, qd = X[:, : model.n_q].T, X[:, model.n_q :].T
    kin, el, grav = (np.array(v, dtype=float).ravel() for v in _mapped(model, "energies", count, q, qd))
    tip = np.array(_mapped(model, "tip", count, q, qd)[0], dtype=float).T
    deflection = np.array(_mapped(model, "deflection", count, q)[0], dtype=float).T
    energies = {"E_kin": kin, "E_el": el, "E_grav": grav, "E_total": kin + el + grav}
    return Trajectory(time=t, states=X, inputs=U, coordinate_names=model.coordinate_names, energies=energies,
                      tip=tip, deflections=deflection, meta=meta)


@dataclass
class ClosedLoopResult:
    """A closed-loop run: the plant trajectory, the metrics and the controller's own report."""

    trajectory: Trajectory
    metrics: dict[str, Any]
    controller: dict[str, Any]
    reference: np.ndarray


def simulate_closed_loop(plant, controller, x0: np.ndarray, duration: float, dt: float, *,
                         sensors=None, rng: np.random.Generator | None = None, compile: bool | None = None,
                         monitor=None, stop_on_divergence: bool = False) -> tuple[Trajectory, np.ndarray]:
    """Run ``controller`` on ``plant`` from ``x0`` for ``duration`` s with plant step ``dt`` s.

    Parameters
    ----------
    monitor : callable, optional
        ``monitor(t, x) -> str | None`` called with the plant state at the end of every
        controller sample; a string (why the run is diverging) stops it like a
        non-finite state.
    stop_on_divergence : bool
        On divergence, return the trajectory up to the last finite state with
        ``meta["divergence"] = {"time": t (s), "reason": str}`` instead of raising.

    Returns
    -------
    trajectory : Trajectory
        At the plant rate; ``inputs`` are the held torques.
    sample_times : ndarray
        Times (s) at which the controller was called.

    Raises
    ------
    SimulationError
        The plant diverged (unless ``stop_on_divergence``).
    """
    t, X, U, meta, samples = integrate_closed_loop(plant, controller, x0, duration, dt, sensors=sensors, rng=rng,
                                                   compile=compile, monitor=monitor,
                                                   stop_on_divergence=stop_on_divergence)
    return trajectory_from_states(plant, t, X, U, meta), samples


def integrate_closed_loop(plant, controller, x0: np.ndarray, duration: float, dt: float, *,
                          sensors=None, rng: np.random.Generator | None = None, compile: bool | None = None,
                          monitor=None, stop_on_divergence: bool = False, stride: int = 1
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any], np.ndarray]:
    """The loop of :func:`simulate_closed_loop` without the trajectory's derived signals.

    Parameters
    ----------
    stride : int
        Keep every ``stride``-th plant sample (a whole divisor of ``Ts/dt``), e.g. to
        compare runs at different plant steps on a common grid of ``stride * dt`` s.

    Returns
    -------
    t : ndarray
        Kept sample times (s), shape (T,).
    X, U : ndarray
        States and held torques (N m) at those times, shapes (T, n_x) and (T, n_u).
    meta : dict
        ``integrator``, ``dt`` (s), ``sample_time`` (s), ``wall_time`` (s, the loop),
        ``compiled``, ``divergence``, ``stride``, ``setup_time`` (s, building and
        compiling or loading the plant's step function).
    sample_times : ndarray
        Times (s) at which the controller was called.
    """
    Ts = controller.sample_time
    substeps = int(round(Ts / dt))
    if substeps < 1 or abs(substeps * dt - Ts) > 1e-9 * Ts:
        raise SpecError(f"plant step {dt:g} s does not divide the controller sample time {Ts:g} s; allowed: Ts/dt a whole number", key="dt")
    if isinstance(stride, bool) or not isinstance(stride, int) or stride < 1 or substeps % stride:
        raise SpecError(f"value {stride!r} is not allowed; allowed: a whole divisor of Ts/dt = {substeps}", key="stride")
    sensors = sensors or controller.sensors
    setup = time.perf_counter()
    advance, compiled = advance_function(plant, substeps, compile)
    setup = time.perf_counter() - setup
    per = substeps // stride
    n_samples = int(math.ceil(duration / Ts - 1e-9))
    X = np.empty((n_samples * per + 1, plant.n_x))
    U = np.empty((n_samples * per + 1, plant.n_u))
    X[0] = x = np.asarray(x0, dtype=float)
    u = np.array(controller.u_previous, dtype=float)
    n_joints = plant.n_u
    wall = time.perf_counter()
    divergence = None
    end = n_samples * per + 1
    samples_done = n_samples
    for k in range(n_samples):
        t = k * Ts
        u = controller.step(t, sensors.measure(x, u, rng))
        block = np.asarray(advance(x, u, dt), dtype=float).T
        rows = slice(k * per + 1, (k + 1) * per + 1)
        X[rows] = block[stride - 1 :: stride]
        U[k * per : (k + 1) * per] = u
        x = block[-1]
        reason = None
        if not np.all(np.isfinite(block)):
            reason = "non-finite plant state"
        elif np.max(np.abs(block[:, n_joints : plant.n_q]), initial=0.0) > MODAL_BOUND:
            reason = f"a modal coordinate beyond {MODAL_BOUND:g} m"
        elif np.max(np.abs(block[:, plant.n_q :])) > RATE_BOUND:
            reason = f"a rate beyond {RATE_BOUND:g}"
        elif monitor is not None:
            reason = monitor(t + Ts, x)
        if reason is not None:
            message = (f"closed loop diverged at t = {t + Ts:.4g} s ({reason}; plant step {dt:g} s, controller sample "
                       f"{Ts:g} s, plant omega_max {plant.omega_max:.4g} rad/s): the controller does not stabilise "
                       f"this plant (or the plant step is too large for RK4: stable below "
                       f"~{2.785 / max(plant.omega_max, 1e-12):.3g} s for the locked-joint modes)")
            if not stop_on_divergence:
                raise SimulationError(message)
            finite = np.all(np.isfinite(X[: (k + 1) * per + 1]), axis=1)
            end = int(np.argmin(finite)) if not np.all(finite) else (k + 1) * per + 1
            end = max(end, 2)
            divergence = {"time": float(t + Ts), "reason": reason, "message": message}
            samples_done = k + 1
            break
    X, U = X[:end], U[:end]
    U[-1] = u
    t = np.arange(X.shape[0]) * (dt * stride)
    meta = {"integrator": "rk4", "dt": dt, "sample_time": Ts, "wall_time": time.perf_counter() - wall,
            "compiled": compiled, "divergence": divergence, "stride": stride, "setup_time": setup}
    return t, X, U, meta, np.arange(samples_done) * Ts


def state_projection(plant, design_names) -> np.ndarray:
    """Matrix ``P`` (n_design x plant.n_x) with ``x_design = P x_plant``: coordinates matched by name.

    An assumed-modes rung keeps the first ``N`` clamped-mass modes of each link, the same
    functions at every ``N`` (a mode's shape and frequency do not depend on how many are
    kept), so coordinate ``qf<link><mode>`` means the same in every ``amm`` model; a design
    coordinate the plant lacks (a mode above the plant's count) reads zero, and the plant's
    modes above the design's are not seen (spillover).

    Raises
    ------
    SpecError
        When a design coordinate the plant lacks is not an elastic one (different arms or
        a finite-element plant: its coordinates are nodal, not modal).
    """
    from flexctrl.linear import state_names

    plant_names = state_names(plant)
    index = {name: i for i, name in enumerate(plant_names)}
    P = np.zeros((len(design_names), plant.n_x))
    for row, name in enumerate(design_names):
        if name in index:
            P[row, index[name]] = 1.0
        elif not re.match(r"^d?qf\d+$", name) or str(getattr(plant, "fidelity", "")).startswith("fem"):
            raise SpecError(f"the full-state controller's coordinate '{name}' has no counterpart in the plant "
                            f"'{plant.name}' ({', '.join(plant.coordinate_names)}); allowed: plant and design models "
                            "that are both assumed-modes ('rigid' or 'amm:N') of the same arm", key="controller_fidelity")
    return P


def plant_sensors(plant, design_sensors, q_joints):
    """The controller's sensor kinds built on the plant model, with the controller's noise levels.

    A full-state controller on a plant of another fidelity measures the plant's state
    projected on the design model's coordinates (:func:`state_projection`).
    """
    from flexctrl.linear import Sensors

    if "state" in design_sensors.kinds:
        if plant.n_x == design_sensors.function.size1_in(0):
            return design_sensors
        P = state_projection(plant, design_sensors.names)
        x = ca.MX.sym("x", plant.n_x)
        u = ca.MX.sym("u", plant.n_u)
        function = ca.Function("sensors", [x, u], [ca.mtimes(ca.DM(P), x)], ["x", "u"], ["y"])
        return dataclasses.replace(design_sensors, function=function)
    built = Sensors.build(plant, design_sensors.kinds, q_joints=q_joints)
    if built.names != design_sensors.names:
        raise SpecError(f"the plant's sensors {list(built.names)} differ from the controller's {list(design_sensors.names)}; "
                        "strain gauges need links with modes in both models", key="controller_fidelity")
    return dataclasses.replace(built, noise_std=np.array(design_sensors.noise_std, dtype=float))


def divergence_monitor(plant, arm, scene, fraction: float, margin: float):
    """``monitor(t, x)`` for :func:`simulate_closed_loop`: link tip deflections and joint excursions.

    A link diverges when its tip deflection exceeds ``fraction`` of its length (m); a
    joint when it leaves the range of its move widened by ``margin`` (rad) on each side.
    """
    n, N = plant.n_u, plant.n_q
    lengths = np.array([link.length for link in arm.links], dtype=float)
    limit = fraction * lengths
    start, target = np.asarray(scene.start_q), np.asarray(scene.target_q)
    low, high = np.minimum(start, target) - margin, np.maximum(start, target) + margin
    deflection = plant.functions["deflection"]

    def monitor(t: float, x: np.ndarray) -> str | None:
        w = np.array(deflection(x[:N])[0], dtype=float).ravel()
        over = np.flatnonzero(np.abs(w) > limit)
        if over.size:
            i = int(over[0])
            return (f"link {i + 1} tip deflection {w[i]:.3g} m beyond {limit[i]:.3g} m "
                    f"(divergence_deflection = {fraction:g} of its {lengths[i]:g} m length)")
        q = x[:n]
        out = np.flatnonzero((q < low) | (q > high))
        if out.size:
            i = int(out[0])
            return (f"joint {i + 1} at {math.degrees(q[i]):.4g} deg, more than divergence_angle = "
                    f"{math.degrees(margin):g} deg outside its move [{math.degrees(start[i]):.4g}, "
                    f"{math.degrees(target[i]):.4g}] deg")
        return None

    return monitor


#: The model a controller is designed on when the plant is ``fidelity = "auto"`` and the scene names no
#: ``controller_fidelity``: the quickstart's plant and design model (two modes per link).
AUTO_DESIGN_FIDELITY = "amm:2"


def pin_design(scene):
    """The scene with its design model pinned when the plant's fidelity is ``auto``.

    The plant is what auto chooses; the controller must not change with it, so it is
    designed on ``controller_fidelity``, or :data:`AUTO_DESIGN_FIDELITY` when the scene
    gives none.  Other scenes are returned unchanged.
    """
    from flexctrl.fidelity import parse_fidelity

    if scene.plant.fidelity.kind != "auto" or scene.controller_fidelity is not None:
        return scene
    return dataclasses.replace(scene, controller_fidelity=parse_fidelity(AUTO_DESIGN_FIDELITY))


@dataclass
class LoopSetup:
    """Everything a closed-loop run needs, built by :func:`build_loop` (see :func:`run_closed_loop_scene`)."""

    scene: Any
    plant_scene: Any
    arm: Any
    plant: Any
    design_arm: Any
    design_fidelity: Any
    design_q: tuple[float, ...]
    design_model: Any
    controller: Any
    settings: Any
    path: Path
    reference: Any
    sensors: Any
    x0: np.ndarray
    monitor: Any
    build_time_s: float


def design_scene_controller(scene, design_model, settings, path: str | Path):
    """Design ``settings`` on ``design_model`` at the scene's design configuration, reset, tracking the scene's path.

    Raises
    ------
    SolverError
        When the design fails numerically (named with the controller file and the configuration).
    """
    from flexctrl.control import design
    from flexctrl.control.reference import ReferenceTrajectory
    from flexctrl.linear import equilibrium

    design_q = tuple(scene.design_configuration)
    op = equilibrium(design_model, design_q)
    where = "the target" if scene.design_q is None else "the design configuration"
    try:
        ctrl = design(design_model, op, settings)
    except FlexctrlError:
        raise
    except Exception as exc:  # numerical failures inside control/scipy/osqp become a clear, recorded error
        raise SolverError(f"designing the '{settings.kind}' controller ({path}) at {where} "
                          f"{np.degrees(design_q).round(3).tolist()} deg failed: {type(exc).__name__}: {exc}") from exc
    ctrl.set_reference(ReferenceTrajectory(design_model, scene.joint_reference(), scene.deflection))
    ctrl.reset()
    return ctrl


def build_loop(scene, controller: str | Path | None = None, overrides=()) -> LoopSetup:
    """Build plant and design models (cached per process), design the controller, set its reference.

    ``scene`` must have a concrete plant fidelity (resolve ``auto`` first).
    """
    from flexctrl.scenes import initial_state, scene_arm
    from flexctrl.spec.controller import load_controller

    start = time.perf_counter()
    plant_scene = scene.plant
    path = controller or scene.controller
    if path is None:
        raise SpecError("no controller: give --controller FILE or the scene key 'controller'", source=scene.source, key="controller")
    settings = load_controller(path, overrides)
    arm = scene_arm(plant_scene)
    if len(scene.target_q) != arm.n_links:
        raise SpecError(f"has {len(scene.target_q)} values; expected {arm.n_links} (one per joint)", source=scene.source, key="target.q")
    plant = _cached_model(arm, plant_scene.fidelity, plant_scene.modes, plant_scene.q0)
    design_arm = arm if scene.design_payload is None else arm.with_payload(scene.design_payload)
    design_fidelity = scene.controller_fidelity or plant_scene.fidelity
    design_q = tuple(scene.design_configuration)
    same = design_arm == arm and str(design_fidelity) == str(plant_scene.fidelity) and scene.design_q is None
    design_model = plant if same else _cached_model(design_arm, design_fidelity, plant_scene.modes, design_q)
    ctrl = design_scene_controller(scene, design_model, settings, path)
    path_ref = scene.joint_reference()
    sensors = ctrl.sensors if same else plant_sensors(plant, ctrl.sensors, design_q)
    x0 = initial_state(plant_scene, plant, arm)
    monitor = divergence_monitor(plant, arm, scene, scene.divergence_deflection, scene.divergence_angle)
    return LoopSetup(scene, plant_scene, arm, plant, design_arm, design_fidelity, design_q, design_model, ctrl, settings,
                     Path(path), path_ref, sensors, x0, monitor, time.perf_counter() - start)


def closed_loop_tip_path(scene, fidelity, dt: float, *, controller: str | Path | None = None, overrides=(),
                         stride: int = 1) -> dict[str, Any]:
    """The closed loop with the plant at ``fidelity`` and RK4 step ``dt`` (s): tip path and torques only.

    Used by :func:`flexctrl.analysis.auto_fidelity.choose_closed_loop_fidelity`.  A
    diverging run stops there (``diverged_at``, s).  The scene's ``controller_fidelity``
    (the design model) is kept, so only the plant changes with ``fidelity``.

    Returns
    -------
    dict
        ``time`` (s), ``tip`` (m, shape (T, 2)) and ``torque`` (N m, (T, n_u)) every
        ``stride`` plant steps; ``wall_time_s`` (the loop), ``build_time_s`` (models,
        design, compiling or loading the plant's step),
        ``omega_max`` (rad/s), ``diverged_at`` (s or None).
    """
    from flexctrl.fidelity import parse_fidelity

    fid = parse_fidelity(fidelity, key="fidelity")
    plant_scene = dataclasses.replace(scene.plant, fidelity=fid, dt=float(dt))
    setup = build_loop(dataclasses.replace(scene, plant=plant_scene), controller, overrides)
    rng = np.random.default_rng(scene.seed) if scene.noise else None
    t, X, U, meta, _ = integrate_closed_loop(setup.plant, setup.controller, setup.x0, plant_scene.duration, float(dt),
                                             sensors=setup.sensors, rng=rng, compile=plant_scene.solver.get("compile"),
                                             monitor=setup.monitor, stop_on_divergence=True, stride=stride)
    plant = setup.plant
    tip = np.array(_mapped(plant, "tip", t.size, X[:, : plant.n_q].T, X[:, plant.n_q :].T)[0], dtype=float).T
    divergence = meta.get("divergence")
    return {"time": t, "tip": tip, "torque": U, "wall_time_s": float(meta["wall_time"]),
            "build_time_s": setup.build_time_s + float(meta["setup_time"]), "omega_max": float(plant.omega_max),
            "diverged_at": None if divergence is None else float(divergence["time"])}


def resolve_auto(scene, controller: str | Path | None = None, overrides=(), **options: Any):
    """For a plant with ``fidelity = "auto"``: the scene with the chosen plant fidelity and step, and the choice.

    The design model is pinned first (:func:`pin_design`); the choice is
    :func:`~flexctrl.analysis.auto_fidelity.choose_closed_loop_fidelity` with the
    scene's ``tolerance`` (cached per process).  Other scenes come back unchanged with None.
    """
    if scene.plant.fidelity.kind != "auto":
        return scene, None
    from flexctrl.analysis.auto_fidelity import check_tolerance, choose_closed_loop_fidelity

    scene = pin_design(scene)
    tol = check_tolerance(scene.plant.tolerance, source=scene.source, key="tolerance")
    choice = choose_closed_loop_fidelity(scene, tol, controller=controller, overrides=tuple(overrides), **options)
    plant = dataclasses.replace(scene.plant, fidelity=choice.choice, dt=choice.dt)
    return dataclasses.replace(scene, plant=plant), choice


def run_closed_loop_scene(scene, out: str | Path | None = None, *, controller: str | Path | None = None,
                          fidelity=None, plots: bool | None = None, overrides=(),
                          on_divergence: str = "raise", auto_options: dict[str, Any] | None = None) -> "SceneResult":
    """Build plant and controller for a closed-loop scene, run it and (with ``out``) write its files.

    Parameters
    ----------
    scene : ClosedLoopScene
    out
        Folder for ``trajectory.csv``, ``summary.json`` (with a ``metrics`` object) and PNGs.
    controller
        Controller file (default: the scene's ``controller``).
    fidelity
        Plant fidelity override (``--fidelity``); ``"auto"`` chooses it (below).
    overrides
        ``KEY=VALUE`` overrides of the controller file.
    on_divergence : {"raise", "record"}
        What a diverging run does (see the module docstring): raise
        :class:`~flexctrl.errors.SimulationError`, or stop and record ``stable = 0``
        and ``divergence_time`` (s) among the metrics.  For such a run every other
        metric covers the run up to the divergence; when that comes before the
        residual-vibration window opens, the window is the last plant sample.  Stable
        runs report ``stable = 1`` and ``divergence_time`` = the scene's duration.  A tip
        that never settles into the band reports ``settled = 0`` and ``settling_time`` =
        the duration (finite: :func:`flexctrl.metrics.settling_time` gives ``inf``).
    auto_options
        Keywords of :func:`~flexctrl.analysis.auto_fidelity.choose_closed_loop_fidelity`
        (``top``, ``reference``, ``safety``, ...) for a plant with ``fidelity = "auto"``.

    Notes
    -----
    With ``fidelity = "auto"`` (scene or override) and the scene's ``tolerance`` (m),
    the controller is designed on ``controller_fidelity`` (default
    :data:`AUTO_DESIGN_FIDELITY`), the plant fidelity and RK4 step are chosen by
    :func:`~flexctrl.analysis.auto_fidelity.choose_closed_loop_fidelity` (cached per
    process by everything that changes the loop), and the run uses them.  The summary
    then holds ``"fidelity_choice"`` (the choice and all its evidence) and the metrics
    ``chosen_modes`` (modes per link of the chosen plant, 0 = rigid), ``chosen_dt``
    (s), ``estimated_error`` and ``reference_error`` (m), ``choice_cost_ratio`` (the
    choice's loop wall time over the reference's) and ``choice_time_s`` (time this
    call spent choosing, s: milliseconds when the choice was cached).
    """
    from flexctrl.fidelity import parse_fidelity
    from flexctrl.linear import equilibrium
    from flexctrl.scenes import SceneResult

    if on_divergence not in ("raise", "record"):
        raise SpecError(f"value {on_divergence!r} is not allowed; allowed: 'raise', 'record'", key="on_divergence")
    if fidelity is not None:
        scene = dataclasses.replace(scene, plant=dataclasses.replace(
            scene.plant, fidelity=parse_fidelity(fidelity, source="--fidelity")))
    requested = scene
    choosing = time.perf_counter()
    scene, choice = resolve_auto(scene, controller, overrides, **(auto_options or {}))
    choosing = time.perf_counter() - choosing
    setup = build_loop(scene, controller, overrides)
    plant_scene, plant, arm, ctrl = setup.plant_scene, setup.plant, setup.arm, setup.controller
    path, settings, path_ref = setup.path, setup.settings, setup.reference
    design_fidelity, design_arm, design_q = setup.design_fidelity, setup.design_arm, setup.design_q
    rng = np.random.default_rng(scene.seed) if scene.noise else None
    trajectory, _ = simulate_closed_loop(plant, ctrl, setup.x0, plant_scene.duration, plant_scene.dt, sensors=setup.sensors,
                                         rng=rng, compile=plant_scene.solver.get("compile"), monitor=setup.monitor,
                                         stop_on_divergence=on_divergence == "record")
    divergence = trajectory.meta.get("divergence")
    target = equilibrium(plant, scene.target_q)
    tip_target = np.array(plant.functions["tip"](target.q, target.qd)[0], dtype=float).ravel()
    n = plant.n_u
    reference = path_ref.joints(trajectory.time)
    report = ctrl.stats.summary()
    allowance = scene.settle_allowance
    if divergence is not None and trajectory.time[-1] < scene.t_arrive + allowance:
        allowance = float(trajectory.time[-1]) - scene.t_arrive - 1e-9  # the window shrinks to the last sample
    metrics = closed_loop_metrics(
        trajectory.time, trajectory.tip, tip_target, trajectory.deflections, trajectory.inputs,
        trajectory.states[:, :n], reference, t_arrive=scene.t_arrive, settle_allowance=allowance, band=scene.band,
        controller_times=ctrl.stats.step_times, fallbacks=report["fallbacks"],
        solver_failures=sum(v for k, v in report["status"].items() if not k.startswith(("ok", "solved", "fallback"))),
    )
    # a tip that never settles (or a run stopped by a divergence) reports the run's duration and
    # settled = 0: finite, so a study row of an unstable loop stays ok (inf would mark it failed)
    metrics["settled"] = int(divergence is None and math.isfinite(metrics["settling_time"]))
    if not metrics["settled"]:
        metrics["settling_time"] = float(plant_scene.duration)
    error = np.linalg.norm(trajectory.tip - tip_target[None, :], axis=1)
    final = trajectory.time >= trajectory.time[-1] - FINAL_WINDOW
    metrics["final_tip_error"] = float(np.max(error[final]))
    metrics["stable"] = int(divergence is None and metrics["final_tip_error"] <= scene.stable_band)
    metrics["divergence_time"] = float(plant_scene.duration) if divergence is None else divergence["time"]
    radius = linear_closed_loop_radius(plant, ctrl, scene.target_q)
    if radius is not None:
        metrics["closed_loop_radius"] = radius
    limits = np.array([j.torque_limit for j in arm.joints])
    metrics["torque_limit_exceeded"] = bool(np.any(np.max(np.abs(trajectory.inputs), axis=0) > limits * (1 + 1e-9)))
    if choice is not None:
        metrics["chosen_modes"] = float(choice.choice.count or 0)
        metrics["chosen_dt"] = float(choice.dt)
        metrics["estimated_error"] = float(choice.estimated_error)
        metrics["reference_error"] = float(choice.reference_error)
        metrics["choice_cost_ratio"] = float(choice.cost_ratio)
        metrics["choice_time_s"] = float(choosing)
    summary = {
        "scene": requested.settings(),
        "controller": {"file": str(path), "kind": settings.kind, "sample_time": ctrl.sample_time, **report},
        "plant": {"fidelity": str(plant_scene.fidelity), "n_states": plant.n_x, "payload_kg": arm.payload.mass},
        "design": {"fidelity": str(design_fidelity), "payload_kg": design_arm.payload.mass,
                   "configuration_deg": np.degrees(design_q).tolist()},
        "reference": path_ref.settings() | {"deflection": scene.deflection},
        "tip_target": tip_target.tolist(),
        "metrics": metrics,
        "divergence": divergence,
        "wall_time_s": trajectory.meta["wall_time"],
    }
    if choice is not None:
        summary["fidelity_choice"] = choice.to_dict()
    files: list[Path] = []
    if out is not None:
        paths = trajectory.save(out, summary)  # summary.json: the trajectory's figures plus this summary
        files += list(paths.values())
        if plant_scene.plots if plots is None else plots:
            files += trajectory.plot(out)
    return SceneResult(scene=scene, trajectory=trajectory, summary=summary, files=files, model=plant)


def _cached_model(arm, fidelity, modes, reference_q):
    """Build a model once per process (study workers run many scenes on the same arm).

    The cache is :func:`flexctrl.analysis.auto_fidelity.cached_model`'s, which the
    fidelity chooser shares.
    """
    from flexctrl.analysis.auto_fidelity import cached_model

    return cached_model(arm, str(fidelity), modes, None if reference_q is None else tuple(reference_q))


# -- the study executor ----------------------------------------------------------------
def _scene_overrides(settings: dict) -> list[str]:
    from flexctrl.study.executors import scene_overrides

    seed = () if settings.get("seed") is None else (f"noise.seed={int(settings['seed'])}",)
    return scene_overrides(settings, seed)


def check_settings(settings: dict) -> None:
    """Validate one study run before any run starts (scene, controller file, model)."""
    from flexctrl.spec.controller import load_controller
    from flexctrl.spec.scene import load_scene
    from flexctrl.study.executors import overrides_for

    scene = load_scene(settings["scene"], _scene_overrides(settings))
    if scene.kind != "closed_loop":
        raise SpecError(f"scene kind '{scene.kind}' is not a closed-loop scene; allowed: kind = \"closed_loop\"", source=str(settings["scene"]), key="kind")
    if settings.get("controller"):
        load_controller(settings["controller"], overrides_for(settings, "controller"))
    if scene.plant.fidelity.kind == "auto":
        check_auto(scene, settings.get("controller"))


def check_auto(scene, controller=None) -> None:
    """Refuse, before any run, a closed loop that ``fidelity = "auto"`` cannot choose for.

    Raises
    ------
    SpecError
        Naming the scene file and key: the tolerance (required, > 0 m), the plant's
        integrator (``rk4``), the design model (``controller_fidelity`` not ``auto``)
        or a missing controller.
    """
    from flexctrl.analysis.auto_fidelity import check_tolerance

    check_tolerance(scene.plant.tolerance, source=scene.source, key="tolerance")
    if scene.plant.integrator != "rk4":
        raise SpecError(f"value '{scene.plant.integrator}' is not allowed with fidelity = 'auto' in a closed loop; "
                        "allowed: 'rk4' (the loop integrates the plant with RK4)", source=scene.source, key="integrator")
    if scene.controller_fidelity is not None and scene.controller_fidelity.kind == "auto":
        raise SpecError("value 'auto' is not allowed for the design model; allowed: 'rigid', 'amm:N' or 'fem:N' "
                        f"(default {AUTO_DESIGN_FIDELITY!r} when the plant is auto)", source=scene.source,
                        key="controller_fidelity")
    if (controller or scene.controller) is None:
        raise SpecError("no controller: give --controller FILE or the scene key 'controller'", source=scene.source,
                        key="controller")


def run_closed_loop(settings: dict):
    """The study executor: one closed-loop run from a settings dict (see :mod:`flexctrl.study.executors`).

    Metrics are flattened to scalars (``peak_torque_1`` ...); trajectories (``t``, joint
    angles, tip position, link deflections, torques) are returned at the plant rate and
    decimated by the study.
    """
    from flexctrl.spec.scene import load_scene
    from flexctrl.study.executors import RunOutput, overrides_for

    scene = load_scene(settings["scene"], _scene_overrides(settings))
    result = run_closed_loop_scene(scene, None, controller=settings.get("controller"),
                                   overrides=overrides_for(settings, "controller"), plots=False, on_divergence="record")
    metrics: dict[str, float] = {}
    for key, value in result.summary["metrics"].items():
        if isinstance(value, list):
            metrics.update({f"{key}_{i + 1}": float(v) for i, v in enumerate(value)})
        else:
            metrics[key] = float(value)
    traj = result.trajectory
    series = {"t": traj.time, "tip_x": traj.tip[:, 0], "tip_y": traj.tip[:, 1]}
    for i in range(traj.inputs.shape[1]):
        series[f"q{i + 1}"] = traj.states[:, i]
        series[f"u{i + 1}"] = traj.inputs[:, i]
        series[f"w{i + 1}"] = traj.deflections[:, i]
    return RunOutput(metrics=metrics, trajectories=series)
