"""The MPC benchmark (``flexctrl bench mpc``): its statistics and the runs it times."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexctrl.bench.mpc_step import default_variants, format_benchmark, mpc_benchmark
from flexctrl.bench.nmpc_step import _run_nmpcs, ms_stats


def test_the_statistics_are_in_milliseconds_and_leave_out_what_is_not_finite():
    stats = ms_stats([0.003, 0.001, math.nan, 0.002, math.inf])
    assert stats == pytest.approx({"median": 2.0, "p95": 2.9, "max": 3.0})
    assert all(math.isnan(v) for v in ms_stats([math.nan]).values())


def test_benchmark_reports_every_variant_with_its_qp_and_a_step_that_contains_the_solve():
    variants = {
        k: v for k, v in default_variants().items() if k in ("osqp_sparse", "osqp_condensed")
    }
    steps, horizon = 5, 5
    result = mpc_benchmark(
        steps=steps, horizon=horizon, variants=variants, python_control_solves=0, nmpc=False
    )
    assert set(result["variants"]) == {"osqp_sparse", "osqp_condensed"}
    for v in result["variants"].values():
        assert v["status"] == {"solved": steps} and v["fallbacks"] == 0
        # every step contains its solve, so the step's statistics bound the solve's
        assert 0 < v["solve_ms"]["median"] <= v["step_ms"]["median"]
        assert v["solve_ms"]["max"] <= v["step_ms"]["max"]
    # 18 states, 3 torques and 3 deflection rows per stage: the sparse QP's variables are
    # (z_k, v_k, s_k) per stage and z_N; the condensed QP keeps the moves and the slacks
    sparse, condensed = result["variants"]["osqp_sparse"], result["variants"]["osqp_condensed"]
    assert sparse["qp_size"]["variables"] == horizon * (18 + 3 + 3) + 18
    assert condensed["qp_size"]["variables"] == horizon * (3 + 3)
    # both forms of one QP regulate alike (to the solver's tolerance)
    assert sparse["final_joint_error_deg"] == pytest.approx(
        condensed["final_joint_error_deg"], abs=1e-2
    )
    assert result["problem"]["states"] == 18 and "mpc_benchmark" in result["command"]
    assert "osqp_condensed" in format_benchmark(result)


def test_the_bench_gives_the_same_runs_per_sample_and_in_blocks(onelink):
    # `flexctrl bench mpc` times the NMPC variants twice, interleaved per sample and in blocks
    # of consecutive samples: every variant has its own plant and is reset, so the order may
    # change the times, not the runs
    model, op = onelink
    dx0 = np.zeros(model.n_x)
    dx0[0] = -0.3
    variants = {
        "warm": {"compile": False, "qp_warm_start": True, "deflection_limit": 0.02},
        "exact": {"compile": False, "sensitivities": "exact", "deflection_limit": 0.02},
    }
    runs = _run_nmpcs(model, op, dx0, 7, 10, 0.02, variants, block_rounds=3)
    for name in variants:
        a, b = runs["sample"][name], runs["block"][name]
        assert a["final_joint_error_deg"] == b["final_joint_error_deg"]
        assert a["status"] == b["status"]
        assert a["final_joint_error_deg"] < np.degrees(0.3)  # the runs moved towards the target
        # every sample once, the statistics reset between the two schedules
        assert sum(a["status"].values()) == sum(b["status"].values()) == 7
