"""Worker affinity of the local pool: the runs that share a model go to one worker, with the same
table."""

from __future__ import annotations

import multiprocessing
from collections import defaultdict

import pytest

from flexctrl.study import load_study, run_study
from flexctrl.study.affinity import AffinityQueue, affinity_key

VOLATILE = ("wall_time_s", "peak_memory_mb", "bytes_written", "worker")


def test_a_worker_keeps_its_group_then_takes_a_free_one_then_shares_the_fullest():
    runs = [
        ("a", 1),
        ("a", 2),
        ("a", 3),
        ("b", 1),
        ("b", 2),
        ("c", 1),
        ("c", 2),
        ("c", 3),
        ("c", 4),
    ]
    queue = AffinityQueue(runs, key=lambda run: run[0])
    assert [queue.next_for(0), queue.next_for(1), queue.next_for(0), queue.next_for(1)] == [
        ("a", 1),
        ("b", 1),
        ("a", 2),
        ("b", 2),
    ]
    assert queue.next_for(1) == ("c", 1)  # b is done: the first group nobody holds
    assert queue.next_for(0) == ("a", 3)
    assert queue.next_for(0) == ("c", 4)  # a is done and c is held: share it, from its end
    assert [queue.next_for(1), queue.next_for(1)] == [("c", 2), ("c", 3)]
    assert not queue and queue.next_for(0) is None


def test_the_key_ignores_the_controller_its_overrides_digest_and_the_seed_only():
    base = {
        "scene": "s.toml",
        "model": "m.toml",
        "payload": 2.0,
        "q0_deg": [0, 90, 0],
        "controller": "lqr.toml",
        "seed": 5,
        "overrides": ["controller.horizon=5", "scene.duration=3"],
        "digests": {"scene": "1", "model": "2", "controller": "3"},
    }
    same = dict(
        base,
        controller="pd.toml",
        seed=9,
        overrides=["scene.duration=3"],
        digests={"scene": "1", "model": "2", "controller": "4"},
    )
    assert affinity_key(base) == affinity_key(same)
    for key, value in (
        ("q0_deg", [0, 0, 0]),
        ("payload", 0.0),
        ("overrides", ["scene.duration=4"]),
        ("digests", {"scene": "1", "model": "5", "controller": "3"}),
        ("fidelity", "amm:3"),
    ):
        assert affinity_key(dict(base, **{key: value})) != affinity_key(base), key


def test_grouped_runs_share_a_worker_and_the_table_is_the_in_process_ones(selftest_study, tmp_path):
    spec = load_study(
        selftest_study, overrides=["set.scene.sleep_s=0.05"]
    )  # 12 configurations x 2 controllers
    grouped = run_study(spec, tmp_path / "grouped", workers=2, progress="none", report=False)
    plain = run_study(spec, tmp_path / "plain", workers=0, progress="none", report=False)
    assert "runs grouped by model per worker" in grouped.backend and "grouped" not in plain.backend

    def strip(table):
        return [{k: v for k, v in row.items() if k not in VOLATILE} for row in table.rows]

    assert strip(grouped.table()) == strip(plain.table())
    workers = defaultdict(set)
    for row in grouped.table().rows:
        workers[(row["payload"], row["q2"], row["q3"])].add(row["worker"])
    assert len(workers) == 12 and len({w for ws in workers.values() for w in ws}) == 2
    split = [cell for cell, ws in workers.items() if len(ws) > 1]
    assert len(split) <= 1, (
        split
    )  # only the last group may be shared, when the other worker runs dry


PRELOAD_PROBE = """
import concurrent.futures as cf, sys
from flexctrl.study.backends import pool_context
context = pool_context({preload!r})
with cf.ProcessPoolExecutor(1, mp_context=context) as pool:
    loaded = "sorted(m for m in __import__('sys').modules if m.startswith('flexctrl.study'))"
    print(pool.submit(eval, loaded).result())
"""


@pytest.mark.skipif(
    "forkserver" not in multiprocessing.get_all_start_methods(), reason="no forkserver here"
)
def test_the_fork_server_imports_the_executors_module_for_its_workers():
    """A worker forked by a preloading server has the executor's module before its first run;
    without it, not.

    The module is the one the registry records for ``_selftest``.  Each probe is a fresh
    interpreter: a process starts its fork server once, so an earlier pool in the test process would
    decide what the server holds.
    """
    import ast
    import subprocess
    import sys

    from flexctrl.study.registry import get_executor

    module = get_executor("_selftest").module
    assert module == "flexctrl.study.executors.selftest_executor"
    loaded = {}
    for preload in (module, None):
        out = subprocess.run(
            [sys.executable, "-c", PRELOAD_PROBE.format(preload=preload)],
            capture_output=True,
            text=True,
            timeout=120,
            check=True,
        ).stdout
        loaded[preload] = set(ast.literal_eval(out.strip().splitlines()[-1]))
    assert {module, "flexctrl.study.backends"} <= loaded[module]
    assert module not in loaded[None] and "flexctrl.study.backends" not in loaded[None]


def test_the_pool_asks_its_fork_server_for_the_executors_registered_module(
    selftest_study, tmp_path, monkeypatch
):
    from flexctrl.study import backends

    asked = []
    real = backends.pool_context
    monkeypatch.setattr(
        backends, "pool_context", lambda preload=None: asked.append(preload) or real(preload)
    )
    spec = load_study(
        selftest_study, overrides=["grid.payload=[2.0]", "grid.q2=[0]", "grid.q3=[0]"]
    )  # 2 runs
    run_study(spec, tmp_path / "pre", workers=1, progress="none", report=False)
    assert asked == ["flexctrl.study.executors.selftest_executor"]
