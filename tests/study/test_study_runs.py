"""Running studies in worker processes: kill and resume, Dask against the local pool, dead
workers."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from flexctrl import cli
from flexctrl.errors import FlexctrlError
from flexctrl.study import load_study, run_study
from flexctrl.study.dask_backend import DaskBackend
from flexctrl.study.store import Table

VOLATILE = ("wall_time_s", "peak_memory_mb", "bytes_written", "worker")


@pytest.fixture
def study(selftest_study) -> Path:
    """The example study and its files copied to tmp_path (isolated from edits of models/)."""
    return selftest_study


def stable(table: Table) -> list[dict]:
    return [{k: v for k, v in row.items() if k not in VOLATILE} for row in table.rows]


def test_killed_study_loses_no_finished_run_and_resumes_to_the_same_table(study, tmp_path, root):
    # 16 runs of 0.3 s each on 2 workers
    slow = study.with_name("slow.toml")
    slow.write_text(
        study.read_text()
        .replace("q3 = [-90, 0, 90]", "q3 = [-90, 90]")
        .replace("[grid]", '[set]\n"scene.sleep_s" = 0.3\n\n[grid]')
    )
    out = tmp_path / "killed"
    cmd = [
        sys.executable,
        "-m",
        "flexctrl.cli",
        "study",
        str(slow),
        "--out",
        str(out),
        "--workers",
        "2",
        "--progress",
        "lines",
    ]
    proc = subprocess.Popen(
        cmd, cwd=root, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    deadline = time.monotonic() + 60
    try:
        while len(list((out / "runs").glob("*.json"))) < 4:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no run finished within 60 s"
            time.sleep(0.02)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the study, its forkserver and its workers
        proc.communicate()
    assert proc.returncode == -signal.SIGKILL

    # no half-written file: every visible file is a complete record or trajectory
    records = sorted((out / "runs").glob("*.json"))
    assert 4 <= len(records) < 16
    for path in (out / "runs").iterdir():
        assert path.name.startswith(".") or path.suffix in (".json", ".npz"), path.name
    for path in records:
        record = json.loads(path.read_text())
        assert record["status"] == "ok"
        with np.load(out / "runs" / record["trajectories"], allow_pickle=False) as npz:
            assert npz["w"].size == record["samples"]
    if (out / "results.csv").exists():  # a table written whole or not at all
        rows = Table.read(out / "results.csv").rows
        assert len(rows) <= 16 and all(len(row["run_id"]) == 16 for row in rows)

    # resume: only the missing runs run; exactly one row per run, as in an uninterrupted study
    spec = load_study(slow)
    resumed = run_study(spec, out, resume=True, workers=2, progress="none", report=False)
    assert resumed.counts["skipped"] == len(records) and resumed.counts["ran"] == 16 - len(records)
    assert not list(out.rglob("*.tmp"))
    reference = run_study(spec, tmp_path / "reference", workers=2, progress="none", report=False)
    table = resumed.table()
    assert len(table) == 16 and len({row["run_id"] for row in table.rows}) == 16
    assert stable(table) == stable(reference.table())
    sessions = json.loads((out / "study.json").read_text())["sessions"]
    assert [s["resume"] for s in sessions] == [False, True] and sessions[0]["end"] is None


def test_sigterm_stops_a_study_like_ctrl_c_and_records_the_session(study, tmp_path, root):
    slow = study.with_name("slow.toml")
    slow.write_text(study.read_text().replace("[grid]", '[set]\n"scene.sleep_s" = 0.3\n\n[grid]'))
    out = tmp_path / "terminated"
    cmd = [
        sys.executable,
        "-m",
        "flexctrl.cli",
        "study",
        str(slow),
        "--out",
        str(out),
        "--workers",
        "2",
        "--progress",
        "none",
    ]
    proc = subprocess.Popen(cmd, cwd=root, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    try:
        while len(list((out / "runs").glob("*.json"))) < 2:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no run finished within 60 s"
            time.sleep(0.02)
        proc.send_signal(
            signal.SIGTERM
        )  # the parent only, as `kill PID` or a batch system's time limit
        proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:  # pragma: no cover
            proc.kill()
    assert proc.returncode == 130
    session = json.loads((out / "study.json").read_text())["sessions"][-1]
    assert (
        session["interrupted"] is True and session["elapsed_s"] > 0 and session["end"] is not None
    )
    assert (out / "results.csv").exists()


def test_local_pool_and_dask_give_identical_tables(study, tmp_path):
    distributed = pytest.importorskip("distributed")
    spec = load_study(study)
    pool = run_study(spec, tmp_path / "pool", workers=2, progress="none", report=False)
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None
    ) as cluster:
        dask = run_study(
            spec,
            tmp_path / "dask",
            scheduler=cluster.scheduler_address,
            progress="none",
            report=False,
        )
    assert pool.counts["ok"] == dask.counts["ok"] == 24
    assert "local process pool, 2 workers" in pool.backend and "dask scheduler" in dask.backend
    assert stable(pool.table()) == stable(dask.table())
    pids = {int(row["worker"].rsplit(":", 1)[1]) for row in pool.table().rows}
    assert len(pids) == 2 and os.getpid() not in pids  # really in two other processes


def test_dask_is_optional(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(FlexctrlError, match=r"pip install 'flexctrl\[dask\]'"):
        DaskBackend("tcp://127.0.0.1:1")
    assert (
        cli.main(["study", "nowhere.toml", "--scheduler", "tcp://x:1"]) == 2
    )  # the file is checked first


def test_a_run_that_kills_its_worker_is_failed_alone_and_the_others_complete(study, tmp_path):
    spec = load_study(
        study,
        overrides=[
            "set.scene.crash_payload=1.0",
            "grid.payload=[0.0, 1.0, 2.0, 3.0]",
            "grid.q3=[0]",
            "grid.q2=[0]",
            'grid.controller=["controllers/soft.toml"]',
        ],
    )
    result = run_study(spec, tmp_path / "out", workers=2, progress="none", report=False)
    rows = {row["payload"]: row for row in result.table().rows}
    assert [rows[p]["status"] for p in (0.0, 1.0, 2.0, 3.0)] == ["ok", "failed", "ok", "ok"]
    assert "worker process died" in rows[1.0]["error"]
