"""Worker affinity for the local pool: the runs that share a model go to the same worker process.

A worker keeps what it built in its :func:`~flexctrl.study.outputs.worker_scene_cache`
(the model of a configuration and payload, its linearisation, reference functions and
output maps), so the second controller run on one configuration costs what its own
design and simulation cost.  Measured on ``studies/payload_configuration_slice.toml``'s
problem (amm:2, 2 kg, one process, warm): a run on a configuration its worker has not
seen pays about 0.33 s more than one on a configuration it has (0.44-0.52 s against
0.09-0.19 s for PD, LQR, shaped and robust).  A process pool hands the next run to
whichever process is free, so on 2 workers every configuration's runs are split between
both and each worker builds every model.

Here every worker is a pool of one process with its own queue, and the runs are grouped
by :func:`affinity_key`: every setting except those of the controller (its file, its
overrides, its digest) and the seed.  A worker takes the next run of its current group;
when that group is used up it starts the next group no worker holds, in plan order; when
none is left it shares the group with the most runs left, taking from its end.  So the
load stays balanced to the last run and no worker idles while runs wait.  Results are
still yielded run by run, as they finish: nothing finished is held back.

A worker process that dies takes the runs in its own queue with it: those are rerun
one at a time on a fresh process of that worker (its other worker keeps going); a run
that kills its worker while alone there is recorded as failed.
"""

from __future__ import annotations

import concurrent.futures as cf
import json
from collections import OrderedDict, deque
from collections.abc import Callable, Iterable, Iterator
from typing import Any

# : Settings that name or tune the controller alone (the model a worker builds does not depend on
# them).
CONTROLLER_KEYS = ("controller", "seed", "replicate")


def affinity_key(settings: dict[str, Any]) -> str:
    """The settings that decide what a worker builds before the controller: all but the controller's
    and the seed.

    Examples
    --------
    >>> a = {"model": "m.toml", "payload": 2.0, "controller": "lqr.toml", "seed": 1,
    ...      "overrides": ["controller.horizon=10", "scene.duration=3"],
    ...      "digests": {"model": "x", "controller": "y"}}
    >>> b = dict(a, controller="pd.toml", seed=2, overrides=["scene.duration=3"],
    ...          digests={"model": "x", "controller": "z"})
    >>> affinity_key(a) == affinity_key(b), affinity_key(a) == affinity_key(dict(a, payload=0.0))
    (True, False)
    """
    kept = {k: v for k, v in settings.items() if k not in CONTROLLER_KEYS}
    if isinstance(kept.get("overrides"), list):
        kept["overrides"] = [o for o in kept["overrides"] if not str(o).startswith("controller.")]
    if isinstance(kept.get("digests"), dict):
        kept["digests"] = {k: v for k, v in kept["digests"].items() if k != "controller"}
    return json.dumps(kept, sort_keys=True, default=str)


class AffinityQueue:
    """The runs still to start, grouped by :func:`affinity_key` in plan order, and which worker
    holds which group."""

    def __init__(self, runs: Iterable[Any], key: Callable[[Any], str]):
        self.groups: OrderedDict[str, deque] = OrderedDict()
        for run in runs:
            self.groups.setdefault(key(run), deque()).append(run)
        self.held: dict[int, str | None] = {}

    def __bool__(self) -> bool:
        return bool(self.groups)

    def next_for(self, worker: int) -> Any | None:
        """The next run for ``worker``: its group's next, a new group's first, or the end of the
        fullest group."""
        group = self.held.get(worker)
        if group is not None and group in self.groups:
            return self._take(group, from_end=False)
        taken = set(self.held.values())
        for candidate in self.groups:
            if candidate not in taken:
                self.held[worker] = candidate
                return self._take(candidate, from_end=False)
        if not self.groups:
            return None
        fullest = max(self.groups, key=lambda g: len(self.groups[g]))
        self.held[worker] = fullest
        return self._take(fullest, from_end=True)

    def _take(self, group: str, *, from_end: bool) -> Any:
        runs = self.groups[group]
        run = runs.pop() if from_end else runs.popleft()
        if not runs:
            del self.groups[group]
        return run


#: The error of a run whose worker process died while it ran alone.
DIED = "its worker process died (killed, out of memory, or a crash in compiled code)"


def outcome(
    future: cf.Future,
    isolated: bool,
    failed: Callable[[str], dict],
    describe: Callable[[BaseException], str],
) -> tuple[dict | None, bool]:
    """``(record, broken)`` of a finished run: its result, or None when it must be rerun alone.

    ``broken``: its worker process died.  A run that was alone in its process when that
    happened (``isolated``) is recorded as failed; with others in flight it is a suspect
    (None).  Any other exception (a result that does not pickle) is a failed record.
    """
    from concurrent.futures.process import BrokenProcessPool

    try:
        return future.result(), False
    except BrokenProcessPool:
        return (failed(f"{DIED} while running this run alone") if isolated else None), True
    except Exception as exc:  # noqa: BLE001 - e.g. a result that does not pickle
        return failed(describe(exc)), False


def run_pinned(
    runs: Iterable[Any],
    workers: int,
    submit: Callable[[cf.Executor, Any], cf.Future],
    make_pool: Callable[[], cf.Executor],
    key: Callable[[Any], str],
    failed: Callable[[str], dict],
    describe: Callable[[BaseException], str],
    window: int = 2,
) -> Iterator[tuple[Any, dict]]:
    """Run ``runs`` on ``workers`` one-process pools with affinity (the module docstring); yields
    ``(run, result)``.

    ``submit(pool, run)`` starts a run, ``make_pool()`` makes a one-process pool, ``failed(text)``
    the record of a failed run, ``describe(exc)`` its one line; ``window`` runs are queued per
    worker.
    """
    queue = AffinityQueue(runs, key)
    suspects: deque = deque()
    pools: list[cf.Executor | None] = [None] * workers
    inflight: dict[cf.Future, tuple[Any, int, bool]] = {}

    def load(worker: int) -> int:
        return sum(1 for _, w, _ in inflight.values() if w == worker)

    try:
        while queue or suspects or inflight:
            for worker in range(workers):
                pool = pools[worker]
                if pool is None:
                    pool = pools[worker] = make_pool()
                if suspects:
                    if load(worker) == 0:  # alone in its process: a death is the run's own
                        run = suspects.popleft()
                        inflight[submit(pool, run)] = (run, worker, True)
                    continue
                while queue and load(worker) < window:
                    run = queue.next_for(worker)
                    inflight[submit(pool, run)] = (run, worker, False)
            if not inflight:
                continue
            done, _ = cf.wait(list(inflight), return_when=cf.FIRST_COMPLETED)
            finished = [(future, *inflight.pop(future)) for future in done]
            broken = set()
            for future, run, worker, isolated in finished:
                result, died = outcome(future, isolated, failed, describe)
                if died:
                    broken.add(worker)
                    # the runs still queued on that process went down with it
                    finished += [
                        (f, *inflight.pop(f))
                        for f, (_, w, _) in list(inflight.items())
                        if w == worker
                    ]
                if result is None:
                    suspects.append(run)
                else:
                    yield run, result
            for worker in broken:
                dead = pools[worker]
                if dead is not None:
                    dead.shutdown(wait=True, cancel_futures=True)
                pools[worker] = None
    finally:
        for pool in pools:
            if pool is not None:
                pool.shutdown(wait=False, cancel_futures=True)


__all__ = ["affinity_key", "AffinityQueue", "run_pinned", "outcome", "DIED"]
