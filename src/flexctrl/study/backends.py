"""Where a study's runs execute: in this process, or on a local process pool.

A backend has ``start()``, ``close()``, ``workers``, ``description`` and
``run(runs, executor, options)``, which yields ``(run, result)`` as runs finish
(:func:`~flexctrl.study.run_execution.execute_run`'s plain results).  A Dask cluster is the
third kind (:mod:`flexctrl.study.dask_backend`).
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
from collections.abc import Iterable, Iterator

from flexctrl.study.affinity import affinity_key, run_pinned
from flexctrl.study.blas_threads import blas_thread_budget, limit_blas_threads, usable_cpus
from flexctrl.study.plan import RunSpec
from flexctrl.study.registry import get_executor
from flexctrl.study.run_execution import describe_exception, execute_run, failed_result


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
        """Each run's result, in order."""
        for run in runs:
            yield run, execute_run(executor, run.settings, options)


def default_workers() -> int:
    """Usable CPUs of this process."""
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
    time (a notebook) gets workers with the installed copy.
    """
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    if preload:
        context.set_forkserver_preload(["__main__", __name__, preload])
    return context


class LocalPoolBackend:
    """A process pool on this machine.

    Every worker is a pool of one process, and the runs that share a model (all settings
    but the controller's) go to the same worker (:mod:`flexctrl.study.affinity`), so a
    configuration's model is built once.  The fork server imports the executor's module
    once before it forks the first worker, so a worker starts with flexctrl, CasADi and
    python-control loaded instead of importing them in its first run (the server is started
    once per Python process: :func:`pool_context`).  Each worker holds its BLAS libraries to
    ``blas_threads`` threads (``"auto"``: usable CPUs // workers, at least 1;
    :mod:`flexctrl.study.blas_threads`): several workers' spinning BLAS threads on few CPUs
    slow every run.  At most ``2 x workers`` runs are in flight.  If a worker process dies
    (killed, out of memory, a crash in compiled code), the runs that were in its queue are
    rerun one at a time on a fresh process: the run that kills its worker again is recorded
    as failed, the others complete.
    """

    def __init__(self, workers: int, blas_threads: int | str = "auto"):
        self.workers = workers
        #: as asked (``"auto"`` or a count); :attr:`threads` is what each worker holds its BLAS to
        self.blas_threads = blas_threads
        self.threads = blas_thread_budget(blas_threads, workers)
        self.description = (
            f"local process pool, {workers} worker{'s' if workers != 1 else ''}, runs grouped "
            f"by model per worker, {self.threads} BLAS thread{'s' if self.threads != 1 else ''} "
            "per worker"
        )

    def pool(self, size: int, context) -> cf.ProcessPoolExecutor:
        """A process pool of ``size`` workers, each holding its BLAS libraries to
        :attr:`threads`."""
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
        """Each run's result as it finishes (see the class docstring)."""
        context = pool_context(get_executor(executor).module)
        yield from run_pinned(
            runs,
            self.workers,
            lambda pool, run: pool.submit(execute_run, executor, run.settings, options),
            lambda: self.pool(1, context),
            lambda run: affinity_key(run.settings),
            failed_result,
            describe_exception,
        )


__all__ = ["InProcessBackend", "LocalPoolBackend", "default_workers", "pool_context"]
