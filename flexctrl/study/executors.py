"""Executors: the code that performs ONE run of a study, looked up by name.

The seam
--------
A run is a plain JSON-able dict of settings, built by :mod:`flexctrl.study.spec`::

    {"executor": "closed_loop",
     "scene": "/abs/studies/scenes/move.toml",      # absolute paths
     "model": "/abs/models/subedi3link.toml",
     "controller": "/abs/controllers/lqr.toml",     # or None (open loop)
     "payload": 2.0,                                 # kg
     "q0_deg": [0.0, 90.0, 0.0],                     # degrees, one per joint
     "fidelity": "amm:2",                            # or None: the model file's own
     "overrides": ["controller.rate_hz=500", "scene.duration=3.0"],  # sorted KEY=VALUE
     "digests": {"scene": "...", "model": "...", "controller": "..."},  # sha256 of the files
     "seed": 2754812377,                             # 32-bit, derived per run
     "replicate": 0}                                 # only when the study has replicates > 1

An executor is a function ``fn(settings: dict) -> RunOutput`` registered under a
name with :func:`register_executor`.  A study file may only *name* an executor
of this registry (``executor = "closed_loop"``); it never imports code.  The
runner calls the function in a worker process (local pool or Dask worker) with
a private copy of the settings, times it, catches every exception (the run is
then recorded as failed with the exception's text) and treats a non-finite
metric as a diverged run.

``overrides`` address the scene, controller or model file: apply them with
``apply_overrides(document, overrides_for(settings, "scene"))`` before the
document is validated, so a misspelt key is rejected by the same reader as the
file.  An executor may register a ``check(settings)`` that :func:`load_study`
calls in the parent for every run BEFORE any run starts: the place to validate
the scene and controller files (with their overrides) so a broken study is
refused up front, with the run's grid coordinates in the message.

Building once per worker
------------------------
Worker processes live for the whole study (and a Dask worker for many
studies), so an expensive build step (compiling the model, designing the
controller) should be a module-level function decorated with
:func:`per_worker_cache` and keyed by the hashable settings that matter,
including the files' digests so an edited file is rebuilt::

    @per_worker_cache(maxsize=8)
    def _build(model_path, model_digest, fidelity, payload):
        ...compile once...

    def run(settings):
        plant = _build(settings["model"], settings["digests"]["model"],
                       settings["fidelity"], settings["payload"])

Never keep solver state in module globals other than such a cache (design
principle: workspaces live in built objects).

Shipped executors
-----------------
``closed_loop``
    :func:`flexctrl.closedloop.run_closed_loop` (imported lazily).  If that
    module defines ``check_settings(settings)``, it is called for every run
    before the study starts.
``_selftest``
    A damped oscillator simulated with numpy in a few milliseconds: its natural
    frequency follows the model's last link, the payload and the configuration,
    its damping the controller file.  It needs no controller code, so it checks
    the runner, the store, the report and a Dask cluster end to end; the test
    suite uses it.  Scene keys (all optional): ``duration`` (s, 2), ``dt``
    (s, 1e-3), ``amplitude`` (m, 0.01), ``noise_std`` (m, 0), ``sleep_s``
    (s, 0: pretend to be slow), ``fail_payload`` (kg: raise for that payload),
    ``crash_payload`` (kg: kill the worker process for that payload; refused in
    the main process).  Controller keys: ``damping_ratio`` (-1..10, negative
    diverges), ``stiffness_gain`` (> -1).  Metrics: ``tip_residual_rms``,
    ``tip_peak``, ``settling_time``, ``frequency_hz``; trajectories ``t``,
    ``w`` (deflection, m), ``w_measured``, ``w_dot``.
"""

from __future__ import annotations

import functools
import importlib
import math
import multiprocessing
import os
import re
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from flexctrl.errors import FlexctrlError, SimulationError, SpecError

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


@dataclass(frozen=True)
class RunOutput:
    """What an executor returns for one run.

    Parameters
    ----------
    metrics
        Scalar metrics by name (SI units; name them with their meaning, e.g.
        ``tip_residual_rms`` in m, ``controller_time_median`` in s).  Values are
        converted to ``float``.
    trajectories
        Optional time histories, each a 1-D numeric array, by name.  By
        convention the sample times are ``"t"`` (s).  The runner decimates them
        and stores them compressed in ``runs/<id>.npz``.

    Raises
    ------
    TypeError
        If a metric is not a real scalar or a trajectory not a 1-D numeric array.
    """

    metrics: Mapping[str, float]
    trajectories: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        metrics = {}
        for name, value in dict(self.metrics).items():
            if not isinstance(name, str) or not name:
                raise TypeError(f"metric name {name!r} is not a non-empty string")
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise TypeError(f"metric '{name}' = {value!r} is not a real scalar")
            metrics[name] = float(value)
        arrays = {}
        for name, value in dict(self.trajectories).items():
            if not isinstance(name, str) or not _NAME.match(name):
                raise TypeError(f"trajectory name {name!r} is not an identifier")
            array = np.asarray(value)
            if array.ndim != 1 or array.dtype.kind not in "biuf":
                raise TypeError(f"trajectory '{name}' has shape {array.shape} and dtype {array.dtype}; expected a 1-D numeric array")
            arrays[name] = array
        object.__setattr__(self, "metrics", metrics)
        object.__setattr__(self, "trajectories", arrays)


ExecutorFn = Callable[[dict], RunOutput]
CheckFn = Callable[[dict], None]


@dataclass(frozen=True)
class Executor:
    """A registered executor: ``run(settings) -> RunOutput`` and an optional ``check``."""

    name: str
    run: ExecutorFn
    check: CheckFn | None = None
    summary: str = ""
    report: Callable[..., list[str]] | None = None
    needs_model: bool = True


_REGISTRY: dict[str, Executor] = {}


def register_executor(name: str, fn: ExecutorFn, *, check: CheckFn | None = None, summary: str = "",
                      report: Callable[..., list[str]] | None = None) -> None:
    """Register ``fn`` as the executor called ``name``.

    Parameters
    ----------
    name
        An identifier; names starting with ``_`` are for self-tests.
    fn
        ``fn(settings: dict) -> RunOutput``; must be a module-level function so
        worker processes can import it by reference.
    check
        Optional ``check(settings)``, called in the parent for every run
        before any run starts; raises :class:`~flexctrl.errors.SpecError`
        for settings the executor cannot run.  Memoise expensive parts.
    summary
        One line for ``flexctrl study --help``.
    report
        Optional ``report(directory, rows, figures) -> list[str]``: extra
        Markdown lines for the study's report, drawn from the result files
        alone (``rows`` are the table's rows as dicts, ``figures`` the folder
        for PNGs).  It may also write derived tables into ``directory``.

    Raises
    ------
    ValueError
        If ``name`` is not an identifier or already names another function.
    """
    if not _NAME.match(name):
        raise ValueError(f"executor name {name!r} is not an identifier")
    existing = _REGISTRY.get(name)
    if existing is not None and existing.run is not fn:
        raise ValueError(f"executor '{name}' is registered already (to {existing.run.__module__}.{existing.run.__qualname__})")
    _REGISTRY[name] = Executor(name, fn, check, summary, report)


def executor_names() -> tuple[str, ...]:
    """Registered names, in registration order."""
    return tuple(_REGISTRY)


def get_executor(name: str, *, source: str | None = None, key: str = "executor") -> Executor:
    """The executor called ``name``.

    Raises
    ------
    SpecError
        Naming the allowed executors.
    """
    if name not in _REGISTRY:
        import difflib

        hint = difflib.get_close_matches(name, list(_REGISTRY), n=1)
        extra = f" (did you mean '{hint[0]}'?)" if hint else ""
        raise SpecError(f"value {name!r} is not a registered executor; allowed: {', '.join(map(repr, _REGISTRY))}{extra}", source=source, key=key)
    return _REGISTRY[name]


# -- helpers for executor authors ----------------------------------------------------


def per_worker_cache(maxsize: int = 8) -> Callable:
    """Decorator: remember a build step per worker process (``functools.lru_cache``).

    Key it by hashable settings (use :func:`freeze` for lists) and include the
    files' digests (``settings["digests"]``) so an edited file is rebuilt.
    """
    return functools.lru_cache(maxsize=maxsize)


def freeze(value: Any) -> Any:
    """A hashable copy of plain data: lists become tuples, dicts sorted item tuples."""
    if isinstance(value, Mapping):
        return tuple(sorted((k, freeze(v)) for k, v in value.items()))
    if isinstance(value, (list, tuple)):
        return tuple(freeze(v) for v in value)
    return value


def overrides_for(settings: Mapping[str, Any], target: str) -> list[str]:
    """The ``KEY=VALUE`` overrides of one file (``"scene"``, ``"controller"`` or ``"model"``), prefix removed.

    Examples
    --------
    >>> overrides_for({"overrides": ["scene.duration=3.0", "model.n=2"]}, "scene")
    ['duration=3.0']
    """
    prefix = target + "."
    return [item[len(prefix):] for item in settings.get("overrides", ()) if item.startswith(prefix)]


def scene_overrides(settings: Mapping[str, Any], extra: tuple[str, ...] = ()) -> list[str]:
    """The run's model, payload, configuration and fidelity as scene ``KEY=VALUE`` overrides,
    then ``extra``, then its ``scene.*`` overrides (which win).

    The run's settings take precedence over the same keys in the scene file (the
    study's grid chose them); ``load_scene(settings["scene"], scene_overrides(settings))``
    gives the run's scene.
    """
    import json

    items = [f"model={json.dumps(str(settings['model']))}"]
    if settings.get("payload") is not None:
        items.append(f"payload={float(settings['payload'])!r}")
    if settings.get("q0_deg") is not None:
        items.append("initial.q=[" + ", ".join(repr(float(a)) for a in settings["q0_deg"]) + "]")
    if settings.get("fidelity") is not None:
        items.append(f"fidelity={json.dumps(str(settings['fidelity']))}")
    return items + list(extra) + overrides_for(settings, "scene")


# -- closed_loop ---------------------------------------------------------------------


def _closed_loop_module():
    try:
        return importlib.import_module("flexctrl.closedloop")
    except ModuleNotFoundError as exc:
        if exc.name != "flexctrl.closedloop":
            raise
        raise FlexctrlError("closed-loop runs need flexctrl.closedloop, which this installation does not have yet") from None


def run_closed_loop(settings: dict) -> RunOutput:
    """The ``closed_loop`` executor: :func:`flexctrl.closedloop.run_closed_loop`."""
    return _closed_loop_module().run_closed_loop(settings)


def check_closed_loop(settings: dict) -> None:
    """Fail early if :mod:`flexctrl.closedloop` is missing; run its ``check_settings(settings)`` if it has one."""
    module = _closed_loop_module()
    check = getattr(module, "check_settings", None)
    if check is not None:
        check(settings)


register_executor("closed_loop", run_closed_loop, check=check_closed_loop, summary="build the model, design the controller, simulate the closed loop (flexctrl.closedloop)")


# -- _selftest -----------------------------------------------------------------------


@dataclass(frozen=True)
class _SelftestScene:
    duration: float
    dt: float
    amplitude: float
    noise_std: float
    sleep_s: float
    fail_payload: float | None
    crash_payload: float | None


@per_worker_cache(maxsize=32)
def _selftest_documents(scene: str, scene_overrides: tuple[str, ...], controller: str | None, controller_overrides: tuple[str, ...], digest_key: tuple) -> tuple[_SelftestScene, float, float]:
    from flexctrl.spec.overrides import apply_overrides
    from flexctrl.spec.reader import TableReader, read_toml

    doc = apply_overrides(read_toml(scene), scene_overrides, source=f"{scene} (overrides)")
    r = TableReader(doc, scene)
    parsed = _SelftestScene(
        duration=r.positive("duration", 2.0, unit="s"),
        dt=r.positive("dt", 1e-3, unit="s"),
        amplitude=r.positive("amplitude", 0.01, unit="m"),
        noise_std=r.nonnegative("noise_std", 0.0, unit="m"),
        sleep_s=r.number("sleep_s", 0.0, low=0.0, high=60.0, unit="s"),
        fail_payload=r.nonnegative("fail_payload", unit="kg") if r.has("fail_payload") else None,
        crash_payload=r.nonnegative("crash_payload", unit="kg") if r.has("crash_payload") else None,
    )
    r.string("source", "")
    r.finish()
    if parsed.duration / parsed.dt > 1e6:
        raise r.error("dt", f"gives {parsed.duration / parsed.dt:.3g} samples; allowed: at most 1e6")
    zeta, gain = 0.005, 0.0
    if controller is not None:
        doc = apply_overrides(read_toml(controller), controller_overrides, source=f"{controller} (overrides)")
        c = TableReader(doc, controller)
        zeta = c.number("damping_ratio", low=-1.0, high=10.0)
        gain = c.number("stiffness_gain", 0.0, low=-1.0, low_open=True)
        c.string("source", "")
        c.string("type", "")
        c.finish()
    return parsed, zeta, gain


def _selftest_inputs(settings: Mapping[str, Any]):
    digests = settings.get("digests", {})
    return _selftest_documents(
        settings["scene"], tuple(overrides_for(settings, "scene")),
        settings.get("controller"), tuple(overrides_for(settings, "controller")),
        (digests.get("scene"), digests.get("controller")),
    )


@per_worker_cache(maxsize=8)
def _selftest_build(model: str, model_digest: str | None, model_overrides: tuple[str, ...]) -> tuple[float, float]:
    """First clamped-free frequency (Hz) and modal mass (kg) of the model's last link; built once per worker."""
    from flexctrl.spec.arm import load_arm

    link = load_arm(model, overrides=model_overrides).links[-1]
    f0 = 1.8751**2 / (2 * math.pi * link.length**2) * math.sqrt(link.EI / link.mass_per_length)
    return f0, 0.25 * link.mass


def _in_main_process() -> bool:
    if multiprocessing.parent_process() is not None:
        return False
    try:
        from distributed import get_worker

        get_worker()
        return False
    except (ImportError, ValueError):
        return True


def _expm(a: np.ndarray) -> np.ndarray:
    """Matrix exponential of a small matrix: scaling and squaring of a 16-term Taylor series."""
    squarings = max(0, int(math.ceil(math.log2(max(np.abs(a).sum(axis=1).max(), 1e-300)))) + 1)
    scaled = a / 2.0**squarings
    term = np.eye(a.shape[0])
    result = term.copy()
    for k in range(1, 17):
        term = term @ scaled / k
        result = result + term
    for _ in range(squarings):
        result = result @ result
    return result


def run_selftest(settings: dict) -> RunOutput:
    """The ``_selftest`` executor (see the module docstring)."""
    scene, zeta, gain = _selftest_inputs(settings)
    payload = float(settings["payload"])
    if scene.sleep_s:
        time.sleep(scene.sleep_s)
    if scene.fail_payload is not None and payload == scene.fail_payload:
        raise RuntimeError(f"selftest failure requested for payload {payload:g} kg (scene key fail_payload)")
    if scene.crash_payload is not None and payload == scene.crash_payload:
        if _in_main_process():
            raise RuntimeError("selftest crash requested, but the run is in the main process (--workers 0); refusing to exit")
        os._exit(70)
    f0, modal_mass = _selftest_build(settings["model"], settings.get("digests", {}).get("model"), tuple(overrides_for(settings, "model")))
    q = np.radians(np.asarray(settings["q0_deg"], dtype=float))
    shape = 1.0 + 0.2 * float(np.mean(np.cos(q[1:]))) if q.size > 1 else 1.0
    freq = f0 * math.sqrt(modal_mass / (modal_mass + payload)) * shape * math.sqrt(1.0 + gain)
    omega = 2 * math.pi * freq
    n = int(round(scene.duration / scene.dt)) + 1
    t = np.arange(n) * scene.dt
    phi = _expm(np.array([[0.0, 1.0], [-omega**2, -2 * zeta * omega]]) * scene.dt)
    states = np.empty((n, 2))
    states[0] = (scene.amplitude * (1.0 + 0.5 * math.sin(q[0])), 0.0)
    limit = 1e3 * scene.amplitude
    for k in range(1, n):
        states[k] = phi @ states[k - 1]
        if abs(states[k, 0]) > limit:
            raise SimulationError(f"diverged: |w| exceeded {limit:g} m at t = {t[k]:.3f} s (damping ratio {zeta:g})")
    rng = np.random.default_rng(settings["seed"])
    measured = states[:, 0] + scene.noise_std * rng.standard_normal(n)
    residual = measured[t >= scene.duration / 2]
    peak = float(np.max(np.abs(measured)))
    above = np.nonzero(np.abs(measured) > 0.05 * peak)[0]
    return RunOutput(
        metrics={
            "tip_residual_rms": float(np.sqrt(np.mean(residual**2))),
            "tip_peak": peak,
            "settling_time": float(t[above[-1]]) if above.size else 0.0,
            "frequency_hz": freq,
        },
        trajectories={"t": t, "w": states[:, 0], "w_measured": measured, "w_dot": states[:, 1]},
    )


def check_selftest(settings: dict) -> None:
    """Validate the run's scene and controller documents (with overrides; memoised)."""
    _selftest_inputs(settings)


register_executor("_selftest", run_selftest, check=check_selftest, summary="self-test: a damped oscillator in numpy (no controller code needed)")


# -- executors whose code lives in a module of their own ------------------------------


def _module_executor(name: str, module: str, summary: str, *, needs_model: bool = True) -> None:
    """Register ``name`` for ``module``, imported only when a run needs it.

    ``needs_model=False``: study files may leave out ``model`` (the run's
    ``model`` and ``payload`` are then None unless given).  The module provides
    ``execute(settings) -> RunOutput`` and optionally
    ``check_settings(settings)`` and ``report_sections(directory, rows, figures)``
    (see :func:`register_executor`).  Lazy import keeps ``flexctrl study``
    start-up fast and lets a worker process find the code by the name alone.
    """

    def load():
        return importlib.import_module(module)

    def run(settings: dict) -> RunOutput:
        return load().execute(settings)

    def check(settings: dict) -> None:
        fn = getattr(load(), "check_settings", None)
        if fn is not None:
            fn(settings)

    def report(directory, rows, figures) -> list[str]:
        fn = getattr(load(), "report_sections", None)
        return [] if fn is None else list(fn(directory, rows, figures))

    run.__qualname__ = run.__name__ = f"run_{name}"
    _REGISTRY[name] = Executor(name, run, check, summary, report, needs_model)


_module_executor("stability_limits", "flexctrl.analysis.stability_study",
                 "largest stable step of each integrator for each model fidelity, beside theory")
_module_executor("speed_vs_accuracy", "flexctrl.analysis.accuracy_study",
                 "tip error against a converged reference and wall time per simulated second")
_module_executor("baumgarte_sweep", "flexctrl.analysis.baumgarte_study",
                 "constraint drift and stability of the beam over supports as gamma = beta sweeps", needs_model=False)
