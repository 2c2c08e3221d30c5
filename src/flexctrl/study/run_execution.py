"""One study run in a worker process: the executor called, its result as plain data.

The parent sends each worker three plain values: the executor's registered name, the
run's settings dict and the store options (which metrics, whether and how to keep
trajectories).  The worker looks the executor up in its own registry
(:func:`execute_run`), so no code travels from a study file to a worker.  A failure of the
run becomes its record; nothing a run does raises into the parent.
"""

from __future__ import annotations

import math
import os
import platform
import socket
import time
import traceback
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.study.plan import RESERVED_COLUMNS


def peak_memory_mb() -> float | None:
    """Peak resident memory of this process so far (MB), or None where unmeasurable."""
    try:
        import resource
    except ImportError:  # pragma: no cover - Windows
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if platform.system() == "Darwin" else peak / 1024


def describe_exception(exc: BaseException) -> str:
    """One line: type, message and the innermost frame (file:line in function)."""
    text = f"{type(exc).__name__}: {exc}".replace("\n", " ")
    frames = traceback.extract_tb(exc.__traceback__)
    if frames:
        last = frames[-1]
        text += f" (at {Path(last.filename).name}:{last.lineno} in {last.name})"
    return text


def _worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def execute_run(executor: str, settings: dict, options: dict) -> dict[str, Any]:
    """Run one study run in this process and return its result as plain data.

    Parameters
    ----------
    executor
        Registered executor name.
    settings
        The run's settings (see :mod:`flexctrl.study.executors`).
    options
        ``metrics`` (names required, or None), ``keep_trajectories`` (bool) and
        ``decimation`` (keep every n-th sample).

    Returns
    -------
    dict
        ``status`` (``"ok"``/``"failed"``), ``error`` (one line), ``warnings`` (the
        distinct warnings the run raised, one line each: a worker prints none), ``metrics``,
        ``trajectories`` (decimated arrays or {}), ``wall_time_s``,
        ``peak_memory_mb`` (of this worker process so far) and ``worker``.
        Never raises for a failure of the run itself.
    """
    from flexctrl.study.outputs import RunOutput
    from flexctrl.study.registry import get_executor

    start = time.perf_counter()
    status, error, metrics, arrays, unavailable = "ok", "", {}, {}, {}
    caught: list[warnings.WarningMessage] = []
    try:
        unavailable = get_executor(executor).unavailable_metrics(dict(settings))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            output = get_executor(executor).run(dict(settings))
        if not isinstance(output, RunOutput):
            raise TypeError(
                f"executor '{executor}' returned {type(output).__name__}; expected a RunOutput"
            )
        metrics = dict(output.metrics)
        notes = {k: v for k, v in output.notes.items() if not math.isfinite(metrics[k])}
        clash = sorted(set(metrics) & set(RESERVED_COLUMNS))
        if clash:
            raise ValueError(
                f"executor '{executor}' returned metrics named like table columns: "
                f"{', '.join(clash)}"
            )
        if options.get("keep_trajectories", True):
            step = int(options.get("decimation", 1))
            arrays = {
                name: np.ascontiguousarray(array[::step])
                for name, array in output.trajectories.items()
            }
        missing = [
            m for m in options.get("metrics") or () if m not in metrics and m not in unavailable
        ]
        if (unavailable or notes) and not missing:
            error = unavailable_note({**unavailable, **notes})
        bad = {k: v for k, v in metrics.items() if not math.isfinite(v) and k not in notes}
        if missing:
            status, error = (
                "failed",
                f"the executor returned no metric {', '.join(map(repr, missing))}; it returned: "
                f"{', '.join(metrics) or 'none'}",
            )
        elif bad:
            status = "failed"
            error = (
                "non-finite metric "
                + ", ".join(f"{k} = {v}" for k, v in bad.items())
                + ": the run diverged or the metric is undefined"
            )
    except Exception as exc:  # noqa: BLE001 - every failure of a run becomes its record
        status, error = "failed", describe_exception(exc)
    return {
        "status": status,
        "error": error,
        "warnings": warning_lines(caught),
        "unavailable": unavailable,
        "metrics": metrics,
        "trajectories": arrays,
        "wall_time_s": time.perf_counter() - start,
        "peak_memory_mb": peak_memory_mb(),
        "worker": _worker_name(),
    }


def warning_lines(caught) -> list[str]:
    """The distinct warnings of a run, one line each (``Category: message``), in order."""
    lines: dict[str, None] = {}
    for w in caught:
        lines[f"{w.category.__name__}: {w.message}".replace("\n", " ")] = None
    return list(lines)


def unavailable_note(unavailable: dict[str, str]) -> str:
    """The one line an ok run records in its ``error`` cell for the metrics it cannot produce
    (metrics with the same reason named together)."""
    by_reason: dict[str, list[str]] = {}
    for metric, reason in unavailable.items():
        by_reason.setdefault(reason, []).append(metric)
    return "; ".join(f"no {', '.join(names)}: {reason}" for reason, names in by_reason.items())


def failed_result(error: str) -> dict[str, Any]:
    return {
        "status": "failed",
        "error": error,
        "metrics": {},
        "trajectories": {},
        "wall_time_s": None,
        "peak_memory_mb": None,
        "worker": "",
    }


__all__ = [
    "describe_exception",
    "execute_run",
    "failed_result",
    "peak_memory_mb",
    "unavailable_note",
]
