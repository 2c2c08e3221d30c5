"""Running a study's runs on a ``dask.distributed`` cluster.

``dask.distributed`` is an optional dependency, imported only here.  At most ``2 x threads``
runs are in flight.  Workers need flexctrl installed and the study's files at the same
absolute paths (a shared file system).  A task whose worker dies is retried by Dask; after
its ``allowed-failures`` the run is recorded as failed.
"""

from __future__ import annotations

import uuid
from collections.abc import Iterable, Iterator
from itertools import islice
from typing import Any

from flexctrl.errors import FlexctrlError
from flexctrl.study.plan import RunSpec
from flexctrl.study.run_execution import describe_exception, execute_run, failed_result


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
                "a Dask scheduler needs dask.distributed, an optional dependency: pip install "
                "'flexctrl[dask]'"
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
                    result = failed_result(describe_exception(exc))
                future.release()
                following = next(queue, None)
                if following is not None:
                    submit(following)
                yield run, result
        finally:
            for future in list(completed.futures):
                future.cancel()


__all__ = ["DaskBackend"]
