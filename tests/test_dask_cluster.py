"""A study on a real multi-process Dask cluster: `dask scheduler` and `dask worker` processes on localhost."""

from __future__ import annotations

import os
import shutil
import threading
import time
from pathlib import Path

import pytest

from flexctrl.study import load_study, run_study

distributed = pytest.importorskip("distributed")

from flexctrl.study.executors.dask_cluster import LocalhostCluster  # noqa: E402

DATA = Path(__file__).resolve().parent / "data"
VOLATILE = ("wall_time_s", "peak_memory_mb", "bytes_written", "worker")


@pytest.fixture
def slow_study(tmp_path, root) -> Path:
    """The example study (24 runs) with 0.3 s per run, its files copied to tmp_path."""
    shutil.copytree(DATA, tmp_path / "tests" / "data")
    (tmp_path / "models").mkdir()
    shutil.copy(root / "models" / "subedi3link.toml", tmp_path / "models")
    study = tmp_path / "tests" / "data" / "study_selftest.toml"
    slow = study.with_name("slow.toml")
    slow.write_text(study.read_text().replace("[grid]", '[set]\n"scene.sleep_s" = 0.3\n\n[grid]'))
    return slow


def stable(table) -> list[dict]:
    return [{k: v for k, v in row.items() if k not in VOLATILE} for row in table.rows]


def test_a_localhost_cluster_gives_the_pool_table_and_survives_a_killed_worker(slow_study, tmp_path):
    spec = load_study(slow_study)
    pool = run_study(spec, tmp_path / "pool", workers=2, progress="none", report=False)
    out = tmp_path / "dask"
    with LocalhostCluster(workers=2, threads=1) as cluster:
        pids = [p.pid for p in cluster.workers]
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
    assert workers == set(pids) and os.getpid() not in workers  # both worker processes ran, not this one
