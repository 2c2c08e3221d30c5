"""Running a study: a local process pool by default, a Dask cluster on request.

The parent sends each worker three plain values: the executor's registered
name, the run's settings dict and the store options (which metrics, whether
and how to keep trajectories).  The worker looks the executor up in its own
registry (:func:`execute_run`), so no code travels from a study file to a
worker.  Results come back as plain data and the parent writes them as they
arrive (see :mod:`flexctrl.study.store` for why the parent is the only writer).

Backends
--------
``workers=0``
    Runs in this process, one after the other (for debuggers and profilers).
local pool (default)
    ``concurrent.futures.ProcessPoolExecutor`` with the ``forkserver`` start
    method (``spawn`` where there is none): safe with threads in the parent
    and workers that live for the whole study, so per-worker caches pay off.
    At most ``2 x workers`` runs are in flight, so the parent holds no more
    than that whatever the grid's size.  If a worker process dies (killed, out
    of memory, a crash in compiled code), the runs that were in flight are
    rerun one at a time in a fresh pool: the run that kills its worker again is
    recorded as failed, the others complete.  By default every worker is a
    pool of one process and the runs that share a model (all settings but the
    controller's) go to the same worker (:mod:`flexctrl.study.affinity`), so a
    configuration's model is built once; ``affinity=False`` (``--no-affinity``)
    is the plain pool, kept for measuring side by side.  The fork server imports
    the executor's module once before it forks the first worker, so a worker
    starts with flexctrl, CasADi and python-control loaded instead of importing
    them in its first run (about 1.3 s a worker on this machine, which used to
    land in that run's ``wall_time_s``); ``preload=False`` (``--no-preload``)
    keeps the imports in the workers.  The server is started once per Python
    process, so the choice holds for the process's first pool (see :func:`pool_context`).
    Each worker holds its BLAS libraries to ``usable CPUs // workers`` threads (at least
    1; Dask's nanny gives its workers 1) (:mod:`flexctrl.study.blas_threads`: on 2 CPUs,
    2 workers' spinning OpenBLAS threads cost the slice's runs about 15 % of their summed
    wall time); ``blas_threads=0`` (``--blas-threads 0``) leaves the libraries' default.
Dask (``scheduler="tcp://host:8786"`` or ``client=...``)
    ``dask.distributed`` (an optional dependency, imported only here), at most
    ``2 x threads`` runs in flight.  Workers need flexctrl installed and the
    study's files at the same absolute paths (a shared file system).  A task
    whose worker dies is retried by Dask; after its ``allowed-failures`` the run
    is recorded as failed.
"""

from __future__ import annotations

import concurrent.futures as cf
import importlib.metadata
import math
import multiprocessing
import os
import platform
import socket
import time
import traceback
import uuid
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from itertools import islice
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.errors import FlexctrlError, SpecError
from flexctrl.study.store import ResultStore, Table, now_iso
from flexctrl.study.study_file import RESERVED_COLUMNS, RunSpec, StudySpec

STUDY_FORMAT = 1
VERSIONED = (
    "flexctrl",
    "numpy",
    "scipy",
    "casadi",
    "control",
    "osqp",
    "matplotlib",
    "dask",
    "distributed",
)


# -- worker side ---------------------------------------------------------------------


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
        ``status`` (``"ok"``/``"failed"``), ``error`` (one line), ``metrics``,
        ``trajectories`` (decimated arrays or {}), ``wall_time_s``,
        ``peak_memory_mb`` (of this worker process so far) and ``worker``.
        Never raises for a failure of the run itself.
    """
    from flexctrl.study.outputs import RunOutput
    from flexctrl.study.registry import get_executor

    start = time.perf_counter()
    status, error, metrics, arrays, unavailable = "ok", "", {}, {}, {}
    try:
        unavailable = get_executor(executor).unavailable_metrics(dict(settings))
        output = get_executor(executor).run(dict(settings))
        if not isinstance(output, RunOutput):
            raise TypeError(
                f"executor '{executor}' returned {type(output).__name__}; expected a RunOutput"
            )
        metrics = dict(output.metrics)
        clash = sorted(set(metrics) & set(RESERVED_COLUMNS))
        if clash:
            raise ValueError(
                f"executor '{executor}' returned metrics named like table columns: {', '.join(clash)}"
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
        if unavailable and not missing:
            error = unavailable_note(unavailable)
        bad = {k: v for k, v in metrics.items() if not math.isfinite(v)}
        if missing:
            status, error = (
                "failed",
                f"the executor returned no metric {', '.join(map(repr, missing))}; it returned: {', '.join(metrics) or 'none'}",
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
        "unavailable": unavailable,
        "metrics": metrics,
        "trajectories": arrays,
        "wall_time_s": time.perf_counter() - start,
        "peak_memory_mb": peak_memory_mb(),
        "worker": _worker_name(),
    }


def unavailable_note(unavailable: dict[str, str]) -> str:
    """The one line an ok run records in its ``error`` cell for the metrics it cannot produce."""
    return "; ".join(f"no {metric}: {reason}" for metric, reason in unavailable.items())


def _failed(error: str) -> dict[str, Any]:
    return {
        "status": "failed",
        "error": error,
        "metrics": {},
        "trajectories": {},
        "wall_time_s": None,
        "peak_memory_mb": None,
        "worker": "",
    }


# -- backends --------------------------------------------------------------------------


class InProcessBackend:
    """Every run in this process, one after the other."""

    description = "in-process"
    workers = 1

    def start(self) -> None:
        """Nothing to start."""

    def close(self) -> None:
        """Nothing to close."""

    def run(
        self, runs: Iterable[RunSpec], executor: str, options: dict
    ) -> Iterator[tuple[RunSpec, dict]]:
        for run in runs:
            yield run, execute_run(executor, run.settings, options)


def default_workers() -> int:
    """Usable CPUs of this process."""
    from flexctrl.study.blas_threads import usable_cpus

    return usable_cpus()


def pool_context(preload: str | None = None):
    """The local pool's start method: ``forkserver`` (``spawn`` where there is none).

    ``preload`` names a module the fork server imports before it forks any worker,
    after ``__main__`` (as by default) and this module (which holds
    :func:`execute_run`).  The list takes effect only if this process has not started
    its fork server yet: a running server keeps what it loaded, and ``preload=None``
    leaves an earlier list in place.  ``spawn`` has no server and ignores it.  The
    server imports with the interpreter's start-up ``sys.path``, not the parent's
    current one, so a parent that put another copy of flexctrl on ``sys.path`` at run
    time (a notebook) gets workers with the installed copy; pass ``preload=False`` to
    the backend there.
    """
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    if preload:
        context.set_forkserver_preload(["__main__", __name__, preload])
    return context


class LocalPoolBackend:
    """A process pool on this machine (see the module docstring)."""

    def __init__(
        self,
        workers: int,
        affinity: bool = True,
        preload: bool = True,
        blas_threads: int | str = "auto",
    ):
        from flexctrl.study.blas_threads import blas_thread_budget

        self.workers = workers
        # : runs that share a model go to the same worker (:mod:`flexctrl.study.affinity`); False:
        # any free worker
        self.affinity = affinity and workers > 1
        # : the fork server imports the executor's module once for all workers; False: each worker
        # in its first run
        self.preload = preload
        # : as asked (``"auto"``, a count, 0); :attr:`threads` is the count each worker holds its
        # BLAS to (0: no limit)
        self.blas_threads = blas_threads
        self.threads = blas_thread_budget(blas_threads, workers)
        self.description = (
            f"local process pool, {workers} worker{'s' if workers != 1 else ''}"
            + (", runs grouped by model per worker" if self.affinity else "")
            + ("" if preload else ", imports in each worker")
            + (
                f", {self.threads} BLAS thread{'s' if self.threads != 1 else ''} per worker"
                if self.threads
                else ", BLAS threads as the libraries start them"
            )
        )

    def pool(self, size: int, context) -> cf.ProcessPoolExecutor:
        """A process pool of ``size`` workers, each holding its BLAS libraries to :attr:`threads` threads."""
        from flexctrl.study.blas_threads import limit_blas_threads

        return cf.ProcessPoolExecutor(
            size, mp_context=context, initializer=limit_blas_threads, initargs=(self.threads,)
        )

    def start(self) -> None:
        """The pool starts with the first run."""

    def close(self) -> None:
        """The pool closes with the last run."""

    def run(
        self, runs: Iterable[RunSpec], executor: str, options: dict
    ) -> Iterator[tuple[RunSpec, dict]]:
        from flexctrl.study.affinity import affinity_key, outcome, run_pinned
        from flexctrl.study.registry import get_executor

        context = pool_context(get_executor(executor).module if self.preload else None)
        if self.affinity:
            yield from run_pinned(
                runs,
                self.workers,
                lambda pool, run: pool.submit(execute_run, executor, run.settings, options),
                lambda: self.pool(1, context),
                lambda run: affinity_key(run.settings),
                _failed,
                describe_exception,
            )
            return
        pending = deque(runs)
        suspects: deque[RunSpec] = deque()
        inflight: dict[cf.Future, tuple[RunSpec, bool]] = {}
        window = 2 * self.workers
        pool = None
        try:
            while pending or suspects or inflight:
                if pool is None:
                    pool = self.pool(self.workers, context)
                if suspects:
                    if not inflight:
                        run = suspects.popleft()
                        inflight[pool.submit(execute_run, executor, run.settings, options)] = (
                            run,
                            True,
                        )
                else:
                    while pending and len(inflight) < window:
                        run = pending.popleft()
                        inflight[pool.submit(execute_run, executor, run.settings, options)] = (
                            run,
                            False,
                        )
                done, _ = cf.wait(list(inflight), return_when=cf.FIRST_COMPLETED)
                broken = False
                for future in done:
                    run, isolated = inflight.pop(future)
                    result, died = outcome(future, isolated, _failed, describe_exception)
                    broken = broken or died
                    if result is None:
                        suspects.append(run)
                    else:
                        yield run, result
                if broken:
                    for future, (run, _) in list(inflight.items()):
                        result, _ = outcome(future, False, _failed, describe_exception)
                        if result is None:
                            suspects.append(run)
                        else:
                            yield run, result
                    inflight.clear()
                    pool.shutdown(wait=True, cancel_futures=True)
                    pool = None
        finally:
            if pool is not None:
                pool.shutdown(wait=False, cancel_futures=True)


class DaskBackend:
    """Runs on a ``dask.distributed`` cluster (see the module docstring).

    Parameters
    ----------
    address
        Scheduler address, e.g. ``tcp://10.0.0.5:8786``.
    client
        An existing ``distributed.Client`` (then ``address`` is unused and the
        client is left open).
    """

    def __init__(self, address: str | None = None, client: Any = None):
        try:
            import distributed  # noqa: F401
        except ImportError:
            raise FlexctrlError(
                "a Dask scheduler needs dask.distributed, an optional dependency: pip install 'flexctrl[dask]'"
            ) from None
        self.address = address
        self.client = client
        self._own = False
        self.description = f"dask scheduler {address}" if address else "dask client"
        self.workers = 0

    def start(self) -> None:
        """Connect to the scheduler (before anything is written).

        Raises
        ------
        FlexctrlError
            If the scheduler cannot be reached within 20 s or has no workers.
        """
        from distributed import Client

        if self.client is None:
            try:
                self.client = Client(self.address, timeout="20s", set_as_default=False)
            except (OSError, TimeoutError, ValueError) as exc:
                raise FlexctrlError(
                    f"could not reach the Dask scheduler at {self.address!r}: {exc}"
                ) from None
            self._own = True
        nthreads = self.client.nthreads()
        self.workers = sum(nthreads.values())
        self.description = (
            f"dask scheduler {self.client.scheduler.address}, {len(nthreads)} "
            f"workers, {self.workers} threads"
        )
        if not self.workers:
            self.close()
            raise FlexctrlError(
                f"the Dask scheduler at {self.address or 'the client'} has no workers"
            )

    def close(self) -> None:
        """Close the client if this backend opened it."""
        if self._own and self.client is not None:
            self.client.close()
            self.client = None
            self._own = False

    def run(
        self, runs: Iterable[RunSpec], executor: str, options: dict
    ) -> Iterator[tuple[RunSpec, dict]]:
        from distributed import as_completed

        client = self.client
        futures: dict[str, RunSpec] = {}
        queue = iter(runs)
        completed = as_completed(loop=client.loop)
        try:
            threads = self.workers

            def submit(run: RunSpec) -> None:
                key = f"flexctrl-run-{run.run_id}-{uuid.uuid4().hex[:8]}"
                future = client.submit(
                    execute_run, executor, run.settings, options, key=key, pure=False
                )
                futures[future.key] = run
                completed.add(future)

            for run in islice(queue, 2 * threads):
                submit(run)
            for future in completed:
                run = futures.pop(future.key)
                try:
                    result = future.result()
                except Exception as exc:  # noqa: BLE001 - KilledWorker, lost connection ...
                    result = _failed(describe_exception(exc))
                future.release()
                following = next(queue, None)
                if following is not None:
                    submit(following)
                yield run, result
        finally:
            for future in list(completed.futures):
                future.cancel()


# -- the study -------------------------------------------------------------------------


def versions() -> dict[str, str]:
    """Installed versions of flexctrl and the libraries that shape its numbers."""
    found = {"python": platform.python_version()}
    for name in VERSIONED:
        try:
            found[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            found[name] = "not installed"
    return found


def machine() -> dict[str, Any]:
    """Platform, CPUs and memory of this machine."""
    info: dict[str, Any] = {
        "platform": platform.platform(),
        "machine": platform.machine(),
        "processor": platform.processor(),
        "hostname": platform.node(),
        "cpu_count": os.cpu_count(),
        "usable_cpus": default_workers(),
    }
    try:
        info["memory_gb"] = round(
            os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") / 2**30, 2
        )
    except (AttributeError, ValueError, OSError):  # pragma: no cover
        pass
    return info


@dataclass
class StudyResult:
    """What :func:`run_study` did.

    Attributes
    ----------
    directory : Path
    counts : dict
        ``ok``, ``failed``, ``pending`` over the whole grid; ``ran`` and
        ``skipped`` in this session.
    elapsed_s : float
        Wall time of this session (s).
    interrupted : bool
        True if stopped by Ctrl-C (finished runs are kept).
    report : Path or None
    backend : str
    """

    directory: Path
    counts: dict[str, int]
    elapsed_s: float
    interrupted: bool = False
    report: Path | None = None
    backend: str = ""
    warnings: list[str] = field(default_factory=list)

    @property
    def table_path(self) -> Path:
        """``results.csv``."""
        return self.directory / "results.csv"

    def table(self) -> Table:
        """``results.csv`` read back."""
        return Table.read(self.table_path)

    def to_pandas(self):
        """``results.csv`` as a pandas DataFrame."""
        return self.table().to_pandas()


def make_backend(
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    affinity: bool = True,
    preload: bool = True,
    blas_threads: int | str = "auto",
):
    """The backend for the given options (see the module docstring); call its ``start()`` and
    ``close()``.

    ``affinity``: the local pool sends the runs that share a model to one worker
    (:mod:`flexctrl.study.affinity`); ``preload``: its fork server imports the executor's module
    once for all workers; ``blas_threads``: BLAS threads per local worker
    (:func:`~flexctrl.study.blas_threads.blas_thread_budget`).
    """
    if scheduler is not None or client is not None:
        if workers is not None:
            raise SpecError(
                "--workers sizes the local pool; with --scheduler the cluster's workers run the study",
                key="--workers",
            )
        return DaskBackend(scheduler, client)
    if workers is not None and workers < 0:
        raise SpecError(
            f"value {workers} is not allowed; allowed: 0 (in this process) or more workers",
            key="--workers",
        )
    if workers == 0:
        return InProcessBackend()
    return LocalPoolBackend(
        workers if workers is not None else default_workers(), affinity, preload, blas_threads
    )


def run_study(
    spec: StudySpec,
    out: str | os.PathLike,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    resume: bool = False,
    progress: str = "auto",
    stream=None,
    report: bool = True,
    affinity: bool = True,
    preload: bool = True,
    blas_threads: int | str = "auto",
) -> StudyResult:
    """Run every run of ``spec`` not yet recorded in ``out``; write the table and the report.

    Parameters
    ----------
    spec
        From :func:`flexctrl.study.study_file.load_study` (validated before anything runs).
    out
        The result folder (see :mod:`flexctrl.study.store`).
    workers
        Local pool size (default: the usable CPUs; 0: in this process).
    scheduler, client
        A Dask scheduler address or client instead of the local pool.
    resume
        Continue an interrupted study: ``out`` must hold it already; runs with
        a record (ok or failed) are kept.  Without it, runs recorded ok are kept
        and failed ones are run again.
    progress
        ``auto``, ``bar``, ``lines`` or ``none`` (see :class:`~flexctrl.study.progress.Progress`).
    stream
        Where the progress goes (default stderr).
    report
        Write ``report.md`` and the figures at the end.
    affinity
        Local pool: the runs that share a model go to the same worker
        (:mod:`flexctrl.study.affinity`); False: each run to whichever worker is free.
    preload
        Local pool: the fork server imports the executor's module once before it forks
        the workers; False: each worker imports it in its first run (the old path: the
        imports land in that run's wall time).
    blas_threads
        Local pool: BLAS threads per worker, ``"auto"`` (usable CPUs // workers, at
        least 1), a whole number, or 0 for the libraries' own default (the old path;
        :mod:`flexctrl.study.blas_threads`).

    Raises
    ------
    SpecError
        If ``out`` holds another study, or ``resume`` finds nothing to resume.
    FlexctrlError
        If another study writes into ``out`` or the Dask scheduler cannot be reached.
    """
    start = time.monotonic()
    store = ResultStore(out)
    previous = store.read_study()
    if resume and previous is None:
        raise SpecError(f"nothing to resume: '{store.dir}' holds no study.json", key="--resume")
    if previous is not None and previous.get("study", {}).get("name") != spec.name:
        raise SpecError(
            f"'{store.dir}' holds the results of study '{previous.get('study', {}).get('name')}', "
            f"not '{spec.name}'; choose another --out",
            key="--out",
        )
    options = {
        "metrics": None if spec.metrics is None else list(spec.metrics),
        "keep_trajectories": spec.keep_trajectories,
        "decimation": spec.decimation,
    }
    backend = make_backend(workers, scheduler, client, affinity, preload, blas_threads)
    backend.start()
    try:
        return _run(
            spec, store, previous, backend, options, resume, progress, stream, report, start
        )
    finally:
        backend.close()


def _run(
    spec: StudySpec,
    store: ResultStore,
    previous: dict | None,
    backend: Any,
    options: dict,
    resume: bool,
    progress: str,
    stream: Any,
    report: bool,
    start: float,
) -> StudyResult:
    from flexctrl.study.progress import Progress

    with store:
        recorded = store.recorded()
        keep = ("ok", "failed") if resume else ("ok",)
        skip = {run.run_id for run in spec.runs if recorded.get(run.run_id) in keep}
        todo = [run for run in spec.runs if run.run_id not in skip]
        if isinstance(backend, LocalPoolBackend) and backend.workers > max(1, len(todo)):
            backend = LocalPoolBackend(
                max(1, len(todo)),
                backend.affinity,
                backend.preload,  # no idle processes for a short resume
                backend.blas_threads,
            )
        store.write_plan(spec.runs)
        document = previous or {"format": STUDY_FORMAT, "start": now_iso(), "sessions": []}
        session: dict[str, Any] = {
            "start": now_iso(),
            "end": None,
            "backend": backend.description,
            "resume": resume,
            "to_run": len(todo),
            "skipped": len(skip),
            "ok": 0,
            "failed": 0,
            "interrupted": False,
        }
        document.update(
            {"study": spec.to_dict(), "versions": versions(), "machine": machine(), "end": None}
        )
        document["sessions"].append(session)
        store.write_study(document)

        bar = Progress(len(todo), skipped=len(skip), label=spec.name, mode=progress, stream=stream)
        interrupted = False
        try:
            if todo:
                for run, result in backend.run(todo, spec.executor, options):
                    store.save(run, result)
                    session[result["status"]] += 1
                    bar.update(result["status"] == "ok")
        except KeyboardInterrupt:
            interrupted = True
        finally:
            bar.close()
            _, counts = store.write_table(columns=spec.columns, metrics=spec.metrics)
            if any("choice_from" in run.settings for run in spec.runs[:1]):
                from flexctrl.study.shared_choice import write_choices

                write_choices(
                    store.dir,
                    spec.runs,
                    {run.run_id: store.read_record(run.run_id) for run in spec.runs},
                )
            session.update(
                {
                    "end": now_iso(),
                    "interrupted": interrupted,
                    "backend": backend.description,
                    "elapsed_s": round(time.monotonic() - start, 3),
                    "parent_peak_memory_mb": peak_memory_mb(),
                }
            )
            document["end"] = session["end"]
            store.write_study(document)
        report_path = None
        if report and not interrupted:
            from flexctrl.study.report import write_report

            report_path = write_report(store.dir)
    counts.update({"ran": session["ok"] + session["failed"], "skipped": len(skip)})
    notes = (
        [
            f"{counts['extra']} record(s) in runs/ belong to no run of this study (left out of results.csv)"
        ]
        if counts.get("extra")
        else []
    )
    return StudyResult(
        store.dir,
        counts,
        time.monotonic() - start,
        interrupted,
        report_path,
        backend.description,
        notes,
    )
