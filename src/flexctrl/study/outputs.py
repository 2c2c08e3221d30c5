"""What a study executor returns, and the helpers its authors use (see
:mod:`flexctrl.study.registry`).

An executor is a function ``fn(settings: dict) -> RunOutput`` (the settings are the
plain dict of :mod:`flexctrl.study.study_file`).  Worker processes live for the whole study,
so expensive build steps are kept per worker: in :func:`worker_scene_cache` (models,
fidelity choices) or behind :func:`per_worker_cache` (keyed by the settings that matter,
including the files' digests so an edited file is rebuilt).
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


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
    empty
        Metrics this run leaves empty, with the reason (a metric undefined for this run, e.g.
        the time an estimate settles when it never does): not missing, not a failure.

    Raises
    ------
    TypeError
        If a metric is not a real scalar or a trajectory not a 1-D numeric array.
    """

    metrics: Mapping[str, float]
    trajectories: Mapping[str, np.ndarray] = field(default_factory=dict)
    empty: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        metrics = {}
        for name, value in dict(self.metrics).items():
            if not isinstance(name, str) or not name:
                raise TypeError(f"metric name {name!r} is not a non-empty string")
            if isinstance(value, (bool, np.bool_)) or not isinstance(
                value, (int, float, np.integer, np.floating)
            ):
                raise TypeError(f"metric '{name}' = {value!r} is not a real scalar")
            metrics[name] = float(value)
        arrays = {}
        for name, value in dict(self.trajectories).items():
            if not isinstance(name, str) or not IDENTIFIER.match(name):
                raise TypeError(f"trajectory name {name!r} is not an identifier")
            array = np.asarray(value)
            if array.ndim != 1 or array.dtype.kind not in "biuf":
                raise TypeError(
                    f"trajectory '{name}' has shape {array.shape} and dtype {array.dtype}; "
                    "expected a 1-D numeric array"
                )
            arrays[name] = array
        object.__setattr__(self, "metrics", metrics)
        object.__setattr__(self, "trajectories", arrays)


ExecutorFn = Callable[[dict], RunOutput]


CheckFn = Callable[[dict], None]


def per_worker_cache(maxsize: int = 8) -> Callable:
    """Decorator: remember a build step per worker process (``functools.lru_cache``).

    Key it by hashable settings (use :func:`freeze` for lists) and include the
    files' digests (``settings["digests"]``) so an edited file is rebuilt.  The worker
    process owns what is kept: numpy arrays in a result (alone or in a tuple) are made
    read-only, so one run cannot change what the next run of the worker is handed.
    """

    def decorate(fn: Callable) -> Callable:
        @functools.lru_cache(maxsize=maxsize)
        @functools.wraps(fn)
        def cached(*args, **kwargs):
            return _read_only(fn(*args, **kwargs))

        return cached

    return decorate


def _read_only(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        value.setflags(write=False)
    elif isinstance(value, tuple):
        for item in value:
            _read_only(item)
    return value


def freeze(value: Any) -> Any:
    """A hashable copy of plain data: lists become tuples, dicts sorted item tuples."""
    if isinstance(value, Mapping):
        return tuple(sorted((k, freeze(v)) for k, v in value.items()))
    if isinstance(value, (list, tuple)):
        return tuple(freeze(v) for v in value)
    return value


def overrides_for(settings: Mapping[str, Any], target: str) -> list[str]:
    """The ``KEY=VALUE`` overrides of one file (``"scene"``, ``"controller"`` or ``"model"``),
    prefix removed.

    Examples
    --------
    >>> overrides_for({"overrides": ["scene.duration=3.0", "model.n=2"]}, "scene")
    ['duration=3.0']
    """
    prefix = target + "."
    return [
        item[len(prefix) :] for item in settings.get("overrides", ()) if item.startswith(prefix)
    ]


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


@functools.lru_cache(maxsize=1)
def worker_scene_cache():
    """This worker process's :class:`~flexctrl.scenes.cache.SceneCache`.

    The worker is the owner: the study runner runs every run of a process through the
    same executors, and a model or a fidelity choice built for one run serves the next
    runs on the same arm.  The cache lives as long as the process (a local pool worker,
    a Dask worker); ``worker_scene_cache().clear()`` empties it.
    """
    from flexctrl.scenes.cache import SceneCache

    return SceneCache(maxsize=32, limits=WORKER_CACHE_LIMITS)


# : Entries a worker keeps of the kinds that hold a model (with everything derived from it: about 19
# MB per
# : configuration of amm:2 with the seven controllers of the sweep).  At 32, as for the other kinds,
# a worker of
# : the 4032-run sweep grew to 1040 MB; with these it stays at about 400 MB from the 12th
# configuration on (one
# : process, seven controllers per configuration, 36 configurations).  8 models cover an
# automatic-fidelity walk
# : (rigid, amm:1..5 and the design model); a configuration's runs are consecutive in a worker
# (affinity).
WORKER_CACHE_LIMITS = {
    "models": 8,
    "references": 8,
    "integrators": 8,
    "designs": 16,
    "verdicts": 16,
}
