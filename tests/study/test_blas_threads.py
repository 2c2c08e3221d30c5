"""The local pool's workers hold their BLAS libraries to usable CPUs // workers threads
(flexctrl.study.blas_threads)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from flexctrl.errors import SpecError
from flexctrl.study import load_study, run_study
from flexctrl.study.backends import LocalPoolBackend, pool_context
from flexctrl.study.blas_threads import (
    blas_thread_budget,
    parse_blas_threads,
    usable_cpus,
)

# : Evaluated in a worker: load NumPy's and SciPy's BLAS (SciPy's may load only now), then report
# every thread count.
PROBE = (
    "(__import__('scipy.linalg'), "
    "__import__('flexctrl.study.blas_threads', "
    "fromlist=['blas_threads_now']).blas_threads_now())[1]"
)


def worker_threads(blas_threads) -> list[int]:
    backend = LocalPoolBackend(2, blas_threads=blas_threads)
    with backend.pool(1, pool_context(None)) as pool:
        return pool.submit(eval, PROBE).result(timeout=120)


def test_the_budget_shares_the_cpus_between_the_workers():
    assert [blas_thread_budget("auto", w, cpus=2) for w in (1, 2, 3)] == [2, 1, 1]
    assert [blas_thread_budget("auto", w, cpus=8) for w in (1, 2, 3, 8, 16)] == [8, 4, 2, 1, 1]
    assert blas_thread_budget(3, 2, cpus=2) == 3
    assert blas_thread_budget("auto", 1) == usable_cpus()


@pytest.mark.parametrize("bad", ["two", "-1", "0", "1.5", ""])
def test_a_bad_option_names_the_option_the_value_and_what_is_allowed(bad):
    with pytest.raises(SpecError, match=r"--blas-threads.*allowed: auto, or a whole number >= 1"):
        parse_blas_threads(bad)
    assert parse_blas_threads(" auto ") == "auto" and parse_blas_threads("3") == 3


@pytest.mark.parametrize("bad", [-1, 0, 1.5, "2", True])
def test_the_budget_refuses_what_is_not_a_count(bad):
    with pytest.raises(SpecError, match="--blas-threads"):
        blas_thread_budget(bad, 2)


@pytest.mark.skipif(usable_cpus() < 2, reason="one CPU: OpenBLAS may not start a second thread")
def test_a_pool_worker_holds_every_blas_library_to_its_budget():
    """Asked for 1 and for 2, the worker reports exactly that for every loaded library, whatever it
    inherited."""
    for threads in (1, 2, 1):
        counts = worker_threads(threads)
        assert len(counts) >= 2, counts  # NumPy's and SciPy's OpenBLAS at least
        assert set(counts) == {threads}, (threads, counts)


def test_the_budget_is_named_in_the_backend_and_the_table_does_not_move(selftest_study, tmp_path):
    spec = load_study(selftest_study, overrides=["grid.payload=[2.0]", "grid.q3=[0]"])  # 4 runs
    limited = run_study(
        spec, tmp_path / "one", workers=2, progress="none", report=False, blas_threads=1
    )
    library = run_study(
        spec, tmp_path / "two", workers=2, progress="none", report=False, blas_threads=2
    )
    assert "2 workers" in limited.backend and "1 BLAS thread per worker" in limited.backend
    assert "2 BLAS threads per worker" in library.backend  # set, whatever the environment says
    volatile = ("wall_time_s", "peak_memory_mb", "bytes_written", "worker")

    def strip(table):
        return [{k: v for k, v in row.items() if k not in volatile} for row in table.rows]

    assert strip(limited.table()) == strip(library.table())


def test_the_command_refuses_a_bad_count_before_anything_runs(selftest_study, tmp_path):
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "flexctrl.cli",
            "study",
            str(selftest_study),
            "--out",
            str(tmp_path / "out"),
            "--blas-threads",
            "many",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 2
    assert (
        "--blas-threads" in out.stderr and "'many'" in out.stderr and "allowed: auto" in out.stderr
    )
    assert not (tmp_path / "out").exists()
