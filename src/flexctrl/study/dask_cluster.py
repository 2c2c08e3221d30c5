"""A real multi-process Dask cluster on this machine.

:class:`LocalhostCluster` starts ``dask scheduler`` and ``dask worker`` as separate
processes (not an in-process ``LocalCluster``), each worker its own process with its own
flexctrl import, talking to the scheduler over TCP on 127.0.0.1 exactly as the machines of a
real cluster would.  The tests use it to check that a study gives the local pool's table and
survives a killed worker; ``benchmarks/dask_throughput.py`` times a study on 1, 2, ...
workers.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import flexctrl
from flexctrl.errors import FlexctrlError
from flexctrl.study.blas_threads import blas_thread_budget, thread_environment

#: seconds to wait for the scheduler's file and for the workers to register
START_TIMEOUT_S = 120.0


def _dask_command() -> str:
    found = shutil.which("dask") or str(Path(sys.executable).with_name("dask"))
    if not Path(found).exists():
        raise FlexctrlError("the 'dask' command was not found: pip install 'flexctrl[dask]'")
    return found


class LocalhostCluster:
    """``dask scheduler`` plus ``workers`` ``dask worker`` processes on 127.0.0.1.

    Parameters
    ----------
    workers
        Worker processes (one ``dask worker`` command each, so one can be killed alone).
    threads
        Threads per worker (a flexctrl run holds the GIL most of the time: use 1).
    nanny
        Run each worker under Dask's nanny, which restarts it when it dies (default: no
        nanny, so a killed worker stays dead).
    directory
        Where the scheduler file and the workers' scratch space go (default: a temporary folder).
    blas_threads
        BLAS threads per worker process, set through the environment variables the
        libraries read when they load: ``"auto"`` (default) ``max(1, usable CPUs // workers)``,
        a whole number, or 0 to pass this process's environment unchanged.  A nanny sets
        them to 1 where the environment does not set them already (Dask's
        ``distributed.nanny.pre-spawn-environ``), so with one these values win too; a worker
        without a nanny would otherwise start a thread per CPU in each library
        (see :mod:`flexctrl.study.blas_threads`).

    Use as a context manager; :attr:`address` is the scheduler's, :attr:`workers` the
    worker ``Popen`` objects (``kill_worker(i)`` sends SIGKILL to one).
    """

    def __init__(
        self,
        workers: int = 1,
        threads: int = 1,
        *,
        nanny: bool = False,
        directory: str | os.PathLike | None = None,
        blas_threads: int | str = "auto",
    ):
        self.n_workers, self.threads, self.nanny = int(workers), int(threads), nanny
        self.blas_threads = blas_thread_budget(blas_threads, self.n_workers)
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        if directory:
            self.directory = Path(directory)
        else:
            self._tmp = tempfile.TemporaryDirectory(prefix="flexctrl-dask-")
            self.directory = Path(self._tmp.name)
        self.scheduler_file = self.directory / "scheduler.json"
        self.scheduler: subprocess.Popen | None = None
        self.workers: list[subprocess.Popen] = []
        self.address = ""

    def _env(self) -> dict:
        env = dict(os.environ)
        # the workers import the same flexctrl as this process: the folder that holds the package
        root = str(Path(flexctrl.__path__[0]).resolve().parent)
        env["PYTHONPATH"] = os.pathsep.join(
            [root] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p]
        )
        return env

    def _worker_env(self) -> dict:
        return {**self._env(), **thread_environment(self.blas_threads)}

    def start(self) -> LocalhostCluster:
        dask = _dask_command()
        self.directory.mkdir(parents=True, exist_ok=True)
        logs = self.directory
        self.scheduler = subprocess.Popen(
            [
                dask,
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--no-dashboard",
                "--scheduler-file",
                str(self.scheduler_file),
            ],
            env=self._env(),
            stdout=subprocess.DEVNULL,
            stderr=open(logs / "scheduler.log", "wb"),
            start_new_session=True,
        )
        deadline = time.monotonic() + START_TIMEOUT_S
        while not self.scheduler_file.exists() or not self.scheduler_file.read_text().strip():
            if self.scheduler.poll() is not None or time.monotonic() > deadline:
                self.close()
                raise FlexctrlError(f"dask scheduler did not start; see {logs / 'scheduler.log'}")
            time.sleep(0.1)
        self.address = json.loads(self.scheduler_file.read_text())["address"]
        for i in range(self.n_workers):
            cmd = [
                dask,
                "worker",
                "--scheduler-file",
                str(self.scheduler_file),
                "--nworkers",
                "1",
                "--nthreads",
                str(self.threads),
                "--no-dashboard",
                "--name",
                f"flexctrl-{i}",
                "--local-directory",
                str(self.directory / f"worker-{i}"),
            ]
            if not self.nanny:
                cmd.append("--no-nanny")
            self.workers.append(
                subprocess.Popen(
                    cmd,
                    env=self._worker_env(),
                    stdout=subprocess.DEVNULL,
                    stderr=open(logs / f"worker-{i}.log", "wb"),
                    start_new_session=True,
                )
            )
        self.wait_for_workers(self.n_workers, deadline - time.monotonic())
        return self

    def wait_for_workers(self, n: int, timeout: float = START_TIMEOUT_S) -> None:
        """Block until ``n`` workers are registered with the scheduler."""
        from distributed import Client

        with Client(self.address, timeout="30s", set_as_default=False) as client:
            try:
                client.wait_for_workers(n, timeout=max(1.0, timeout))
            except (TimeoutError, OSError) as exc:
                self.close()
                raise FlexctrlError(
                    f"{n} dask workers did not register within {timeout:.0f} s: {exc}; "
                    f"see {self.directory}/worker-*.log"
                ) from None

    def kill_worker(self, i: int) -> int:
        """SIGKILL worker ``i`` (its whole process group); returns its pid."""
        proc = self.workers[i]
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
        return proc.pid

    def close(self) -> None:
        """Stop the workers, then the scheduler (SIGTERM, then SIGKILL after 10 s)."""
        for proc in [*self.workers, *([self.scheduler] if self.scheduler else [])]:
            if proc.poll() is None:
                try:
                    os.killpg(proc.pid, signal.SIGTERM)
                    proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait(timeout=10)
                except ProcessLookupError:
                    pass
        self.workers, self.scheduler = [], None
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __enter__(self) -> LocalhostCluster:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()
