"""BLAS threads in the local pool's workers: no more threads in all than the machine has CPUs.

NumPy and SciPy each load their own OpenBLAS, and OpenBLAS starts one thread per CPU by
default.  A study's linear algebra is small (matrices of 6-30 rows: Riccati equations,
Kalman gains, discretizations, the MPC's set-up), too small for a second thread to help,
but an OpenBLAS thread that has finished its share spins for a while before it sleeps.  With
as many workers as CPUs that is twice as many busy threads as CPUs, and every worker's run
waits for the other workers' spinning threads.

A Dask worker started by ``dask worker`` (under its nanny) already gets
``OMP_NUM_THREADS = MKL_NUM_THREADS = OPENBLAS_NUM_THREADS = 1``
(``distributed.nanny.pre-spawn-environ`` in distributed's own configuration); this module
gives the local pool (and ``LocalhostCluster``'s workers, started without a nanny) the same
rule, sized to the machine: ``auto`` is ``max(1, usable CPUs // workers)`` threads per
worker, so one worker on 2 CPUs keeps the libraries' default of 2 and two workers get 1 each.

A worker limits its threads when it starts (:func:`limit_blas_threads`, the pool's
``initializer``): the libraries already loaded (the fork server imports them before
forking) through :mod:`threadpoolctl`, and any loaded later in the worker through the
environment variables they read when they load.
"""

from __future__ import annotations

import os

from flexctrl.errors import SpecError

#: The environment variables a BLAS or OpenMP library reads for its thread count when it loads.
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def usable_cpus() -> int:
    """The CPUs this process may run on (its affinity mask; ``os.cpu_count()`` where there is
    none)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def blas_thread_budget(setting: int | str, workers: int, cpus: int | None = None) -> int:
    """BLAS threads per worker for ``setting`` (``"auto"``, or a whole number >= 1).

    Parameters
    ----------
    setting
        ``"auto"``: ``max(1, cpus // workers)``; an int >= 1: that many; 0: no limit (returns 0).
    workers
        Worker processes sharing the machine.
    cpus
        Usable CPUs (default: :func:`usable_cpus`).

    Raises
    ------
    SpecError
        If ``setting`` is neither ``"auto"`` nor a whole number >= 0 (names ``--blas-threads``).

    Examples
    --------
    >>> import functools
    >>> budget = functools.partial(blas_thread_budget, "auto")
    >>> budget(2, cpus=2), budget(1, cpus=2), budget(3, cpus=8)
    (1, 2, 2)
    >>> blas_thread_budget(3, 2, cpus=2)
    3
    """
    if setting == "auto":
        return max(1, (usable_cpus() if cpus is None else cpus) // max(1, workers))
    if isinstance(setting, bool) or not isinstance(setting, int) or setting < 1:
        raise SpecError(
            f"value {setting!r} is not allowed; allowed: 'auto' (usable CPUs // workers, at "
            "least 1) or a whole number >= 1 of BLAS threads per worker",
            key="--blas-threads",
        )
    return setting


def parse_blas_threads(text: str) -> int | str:
    """``--blas-threads`` from the command line: ``auto`` or a whole number >= 0.

    Raises
    ------
    SpecError
        For anything else, naming the option, the value and what is allowed.
    """
    text = text.strip()
    if text == "auto":
        return "auto"
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or value < 1:
        raise SpecError(
            f"value {text!r} is not allowed; allowed: auto, or a whole number >= 1 of BLAS "
            "threads per worker",
            key="--blas-threads",
        )
    return value


def thread_environment(threads: int) -> dict[str, str]:
    """The environment variables that hold libraries loaded later to ``threads`` threads (none for
    0)."""
    return {name: str(threads) for name in THREAD_VARIABLES} if threads > 0 else {}


def limit_blas_threads(threads: int) -> None:
    """Hold this process's BLAS and OpenMP libraries to ``threads`` threads (a pool worker's
    initializer).

    The libraries loaded already are limited through :mod:`threadpoolctl`; the environment
    variables of :data:`THREAD_VARIABLES` are set for any library loaded later.
    ``threads = 0`` changes nothing.
    """
    if threads <= 0:
        return
    os.environ.update(thread_environment(threads))
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=threads)


def blas_threads_now() -> list[int]:
    """The thread count of every BLAS and OpenMP library loaded in this process (for tests and
    reports)."""
    from threadpoolctl import threadpool_info

    return [int(info["num_threads"]) for info in threadpool_info()]


__all__ = [
    "THREAD_VARIABLES",
    "blas_thread_budget",
    "blas_threads_now",
    "limit_blas_threads",
    "parse_blas_threads",
    "thread_environment",
    "usable_cpus",
]
