"""A study on a real multi-process Dask cluster: `dask scheduler` and `dask worker` processes on
localhost."""

from __future__ import annotations

import os
import shutil
import threading
import time
from pathlib import Path

import pytest

from flexctrl.study import load_study, run_study

distributed = pytest.importorskip("distributed")

from support import DATA as SHIPPED  # noqa: E402
from support import ROOT  # noqa: E402

from flexctrl.study.blas_threads import THREAD_VARIABLES, blas_thread_budget  # noqa: E402
from flexctrl.study.dask_cluster import LocalhostCluster  # noqa: E402

TEST_DATA = ROOT / "tests" / "data"
VOLATILE = ("wall_time_s", "peak_memory_mb", "bytes_written", "worker")


@pytest.fixture
def slow_study(tmp_path, root) -> Path:
    """The example study (24 runs) with 0.3 s per run, its files copied to tmp_path."""
    shutil.copytree(TEST_DATA, tmp_path / "tests" / "data")
    (tmp_path / "models").mkdir()
    shutil.copy(SHIPPED / "models" / "subedi3link.toml", tmp_path / "models")
    study = tmp_path / "tests" / "data" / "study_selftest.toml"
    slow = study.with_name("slow.toml")
    slow.write_text(study.read_text().replace("[grid]", '[set]\n"scene.sleep_s" = 0.3\n\n[grid]'))
    return slow


def stable(table) -> list[dict]:
    return [{k: v for k, v in row.items() if k not in VOLATILE} for row in table.rows]


def test_a_localhost_cluster_gives_the_pool_table_and_survives_a_killed_worker(
    slow_study, tmp_path, monkeypatch
):
    for name in (
        THREAD_VARIABLES
    ):  # as outside `make test` (which sets them to 1): the workers get the budget from us
        monkeypatch.delenv(name, raising=False)
    spec = load_study(slow_study)
    pool = run_study(spec, tmp_path / "pool", workers=2, progress="none", report=False)
    out = tmp_path / "dask"
    with LocalhostCluster(workers=2, threads=1) as cluster:
        pids = [p.pid for p in cluster.workers]
        assert worker_blas_threads(cluster) == {
            pid: [blas_thread_budget("auto", 2)] * 2 for pid in pids
        }
        killed: dict = {}

        def kill_after_some_runs():
            deadline = time.monotonic() + 120
            while len(list((out / "runs").glob("*.json"))) < 4 and time.monotonic() < deadline:
                time.sleep(0.02)
            killed["done"] = len(list((out / "runs").glob("*.json")))
            killed["pid"] = cluster.kill_worker(0)  # SIGKILL, no nanny: it stays dead

        killer = threading.Thread(target=kill_after_some_runs)
        killer.start()
        result = run_study(spec, out, scheduler=cluster.address, progress="none", report=False)
        killer.join()
        assert cluster.workers[0].poll() is not None and cluster.workers[1].poll() is None
    assert killed["pid"] == pids[0] and 4 <= killed["done"] < 24  # killed mid-study
    table = result.table()
    assert result.counts["ok"] == 24 and len(table) == 24
    assert len({row["run_id"] for row in table.rows}) == 24  # no run lost, none twice
    assert len(list((out / "runs").glob("*.json"))) == 24
    assert stable(table) == stable(pool.table())
    assert "dask scheduler tcp://127.0.0.1:" in result.backend and "2 workers" in result.backend
    workers = {int(row["worker"].rsplit(":", 1)[1]) for row in table.rows}
    assert (
        workers == set(pids) and os.getpid() not in workers
    )  # both worker processes ran, not this one


def worker_blas_threads(cluster: LocalhostCluster) -> dict[int, list[int]]:
    """Each worker's pid and the thread counts of NumPy's and SciPy's BLAS, once both are loaded
    there."""
    from distributed import Client

    def in_worker() -> tuple[int, list[int]]:  # nested, so cloudpickle sends it by value
        import os

        import numpy  # noqa: F401
        import scipy.linalg  # noqa: F401

        from flexctrl.study.blas_threads import blas_threads_now

        return os.getpid(), blas_threads_now()

    with Client(cluster.address, timeout="30s", set_as_default=False) as client:
        return dict(client.run(in_worker).values())


def test_cluster_workers_get_the_blas_thread_budget_in_their_environment(monkeypatch):
    for name in THREAD_VARIABLES:
        monkeypatch.setenv(name, "7")
    auto = LocalhostCluster(workers=2)
    assert auto.blas_threads == blas_thread_budget("auto", 2)
    assert all(auto._worker_env()[name] == str(auto.blas_threads) for name in THREAD_VARIABLES)
    assert all(
        LocalhostCluster(workers=2, blas_threads=3)._worker_env()[name] == "3"
        for name in THREAD_VARIABLES
    )
    assert all(
        auto._env()[name] == "7" for name in THREAD_VARIABLES
    )  # the scheduler's is left as it is
