"""The executor registry: the code that performs ONE run of a study, looked up by name.

The seam
--------
A run is a plain JSON-able dict of settings, built by :mod:`flexctrl.study.study_file`::

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
controller) should be kept per worker: models and fidelity choices in
:func:`~flexctrl.study.outputs.worker_scene_cache`, other builds in a
module-level function decorated with :func:`~flexctrl.study.outputs.per_worker_cache`
and keyed by the hashable settings that matter, including the files' digests so an
edited file is rebuilt::

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
Each lives in a module of :mod:`flexctrl.study.executors`, imported only when a run
needs it, with ``execute(settings)`` and optionally ``check_settings(settings)`` and
``report_sections(directory, rows, figures)``; :data:`BUILTIN` names them.

``closed_loop``
    :mod:`flexctrl.study.executors.closed_loop_executor`: build the model, design the
    controller, simulate the closed loop.
``stability_limits``, ``speed_vs_accuracy``, ``baumgarte_sweep``
    The analyses' studies (:mod:`flexctrl.study.executors.stability_limits_executor` ...).
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

import importlib
from collections.abc import Callable
from dataclasses import dataclass

from flexctrl.errors import SpecError
from flexctrl.study.outputs import IDENTIFIER, CheckFn, ExecutorFn, RunOutput


@dataclass(frozen=True)
class Executor:
    """A registered executor: ``run(settings) -> RunOutput`` and an optional ``check``."""

    name: str
    run: ExecutorFn
    check: CheckFn | None = None
    summary: str = ""
    report: Callable[..., list[str]] | None = None
    needs_model: bool = True
    unavailable: Callable[[dict], dict[str, str]] | None = None
    # : the module that holds the executor's code, which a local pool's fork server imports once for
    # its workers
    module: str | None = None

    def unavailable_metrics(self, settings: dict) -> dict[str, str]:
        """``{metric: reason}`` of the metrics this run cannot produce, known from its settings
        alone."""
        return {} if self.unavailable is None else dict(self.unavailable(settings))


_REGISTRY: dict[str, Executor] = {}


def register_executor(
    name: str,
    fn: ExecutorFn,
    *,
    check: CheckFn | None = None,
    summary: str = "",
    report: Callable[..., list[str]] | None = None,
) -> None:
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
    if not IDENTIFIER.match(name):
        raise ValueError(f"executor name {name!r} is not an identifier")
    existing = _REGISTRY.get(name)
    if existing is not None and existing.run is not fn:
        raise ValueError(
            f"executor '{name}' is registered already (to "
            f"{existing.run.__module__}.{existing.run.__qualname__})"
        )
    _REGISTRY[name] = Executor(name, fn, check, summary, report, module=fn.__module__)


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
        raise SpecError(
            f"value {name!r} is not a registered executor; allowed: "
            f"{', '.join(map(repr, _REGISTRY))}{extra}",
            source=source,
            key=key,
        )
    return _REGISTRY[name]


def _module_executor(name: str, module: str, summary: str, *, needs_model: bool = True) -> None:
    """Register ``name`` for ``module``, imported only when a run needs it.

    ``needs_model=False``: study files may leave out ``model`` (the run's
    ``model`` and ``payload`` are then None unless given).  The module provides
    ``execute(settings) -> RunOutput`` and optionally
    ``check_settings(settings)``, ``report_sections(directory, rows, figures)`` (see
    :func:`register_executor`) and ``unavailable_metrics(settings) -> {metric: reason}``:
    the metrics a run cannot produce, known from its settings before it runs (e.g. the
    linear verdict of a controller without a linear law); a study asking for one records
    an empty cell and the reason instead of failing the run.  Lazy import keeps ``flexctrl study``
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

    def unavailable(settings: dict) -> dict[str, str]:
        fn = getattr(load(), "unavailable_metrics", None)
        return {} if fn is None else fn(settings)

    run.__qualname__ = run.__name__ = f"run_{name}"
    _REGISTRY[name] = Executor(name, run, check, summary, report, needs_model, unavailable, module)


# : The shipped executors: name -> (module, one line for ``flexctrl study --help``, needs a model
# file).
BUILTIN: dict[str, tuple[str, str, bool]] = {
    "closed_loop": (
        "flexctrl.study.executors.closed_loop_executor",
        "build the model, design the controller, simulate the closed loop",
        True,
    ),
    "_selftest": (
        "flexctrl.study.executors.selftest_executor",
        "a damped oscillator in numpy: checks the runner, store, report and backends",
        True,
    ),
    "stability_limits": (
        "flexctrl.study.executors.stability_limits_executor",
        "largest stable step of each integrator for each model fidelity, beside theory",
        True,
    ),
    "speed_vs_accuracy": (
        "flexctrl.study.executors.speed_vs_accuracy_executor",
        "tip error against a converged reference and wall time per simulated second",
        True,
    ),
    "baumgarte_sweep": (
        "flexctrl.study.executors.baumgarte_sweep_executor",
        "constraint drift and stability of the beam over supports as gamma = beta sweeps",
        False,
    ),
}
for _name, (_module, _summary, _needs_model) in BUILTIN.items():
    _module_executor(_name, _module, _summary, needs_model=_needs_model)
