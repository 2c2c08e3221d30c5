"""The headline table: every figure with its value, unit and the command that measures it."""

from __future__ import annotations

from flexctrl.bench.headline import markdown
from flexctrl.cli import main


def _result(**extra):
    base = {
        "machine": {
            "processor": "x86_64",
            "cpus": 2,
            "python": "3.11.7",
            "date": "2026-12-05 19:00 UTC",
            "load_average_1min": 1.25,
        },
        "quick": False,
        "accuracy": {
            "table3": {"frequencies": 12, "max_abs_error_hz": 0.00341},
            "rk4": {
                "max_q_error_rk4_dt_vs_rk4_dt_over_10": 0.0483,
                "max_q_error_scipy_vs_rk4_dt_over_10": 1.08e-4,
            },
        },
        "simulation": {"realtime_factor_compiled": 153.2, "ratio_vs_scipy": 4612.0},
        "mpc": {"sample_time_ms": 10.0, "mpc_median_ms": 0.571, "mpc_p95_ms": 0.74},
        "loop": {"run_wall_s": 0.259, "plant_only_s": 0.136, "ratio": 1.904},
    }
    return base | extra


def test_the_table_names_machine_date_and_every_figure_with_its_command():
    text = markdown(_result(study={"runs": 32, "workers": 2, "runs_per_min": 43.4}))
    head, _, *rows = text.strip().splitlines()
    assert "2026-12-05 19:00 UTC" in head and "2 CPUs" in head and "load average 1.2" in head
    cells = {row.split(" | ")[0].lstrip("| "): row.split(" | ")[1] for row in rows[2:]}
    assert cells["Table 3 (Subedi et al. 2021), largest frequency error"] == "0.0034 Hz over 12"
    assert cells["linear MPC step (OSQP, warm), median / p95"] == (
        "0.57 / 0.74 ms (sample 10.0 ms)"
    )
    assert cells["quickstart study throughput"] == "43 runs/min (32 runs, 2 workers)"
    assert all(row.rstrip().endswith("` |") for row in rows[2:])  # each names its command


def test_rows_that_were_not_measured_are_left_out():
    text = markdown(_result())
    assert "throughput" not in text and "NMPC" not in text and "python-control" not in text


def test_bench_all_refuses_a_negative_worker_count(capsys):
    assert main(["bench", "all", "--workers", "-1"]) == 2
    assert "--workers" in capsys.readouterr().err
