"""The headline figures, measured side by side in one run: ``flexctrl bench all``.

One process measures, one after the other and on the same machine state:

* **accuracy**: the largest distance of the clamped-mass eigenproblem from Subedi et al.'s
  (2021) Table 3 (12 frequencies, 0/2/4 kg; the paper prints them to 0.01 Hz), and the
  joint-angle errors of the compiled RK4 (1 ms) and of scipy's RK45 after the simulation
  benchmark's 1 s of free vibration, against RK4 at a tenth of the step (RK4 at 1 ms runs at
  ``omega_max h`` of about 2, stable but with its fastest mode's phase off);
* **simulation speed** (:func:`flexctrl.bench.simulation_speed.bench_sim`): simulated seconds
  per wall second of the three-link arm (``amm:2``, 1 ms RK4), compiled, and its ratio to
  scipy's ``solve_ivp``;
* **linear MPC and NMPC step** (:func:`flexctrl.bench.mpc_step.mpc_benchmark`): median and 95th
  percentile solve of the warm-started sparse OSQP MPC and the NMPC's real-time iteration, and
  python-control's ``create_mpc_iosystem`` on the same problem;
* **closed-loop overhead** (:func:`flexctrl.bench.loop_overhead.bench_loop`): a warm LQR run of
  the 30 degree move against the plant's compiled simulation alone;
* **study throughput** (added by the command, which sits above the study layer): the
  quickstart study (32 closed-loop runs) on two workers, runs per minute of wall time.

Every figure carries the machine, the date and the load average it was measured at;
:func:`markdown` writes the table the documentation includes (``docs/reference/benchmarks.md``).
"""

from __future__ import annotations

import datetime
import os
import platform
import time
from typing import Any

from flexctrl.bench.loop_overhead import bench_loop
from flexctrl.bench.mpc_step import default_variants, mpc_benchmark
from flexctrl.bench.nmpc_step import default_nmpc_variants
from flexctrl.bench.simulation_speed import DEFAULT_MODEL, bench_sim
from flexctrl.modal.identify import table3_residuals
from flexctrl.spec.arm import load_arm


def _machine() -> dict[str, Any]:
    """Where and when: host, CPU count, Python, date (UTC), 1-minute load average."""
    return {
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
    }


def _table3() -> dict[str, Any]:
    """Largest |model - Table 3| (Hz) over the paper's 12 frequencies."""
    residuals = [abs(row[-1]) for row in table3_residuals(load_arm(DEFAULT_MODEL))]
    return {"frequencies": len(residuals), "max_abs_error_hz": max(residuals)}


def headline(*, quick: bool = False) -> dict[str, Any]:
    """Measure the headline figures below the study layer (module docstring); JSON-ready.

    Parameters
    ----------
    quick : bool
        Fewer repeats, samples and solves (the same code, noisier figures).

    Returns
    -------
    dict
        ``machine``, ``quick``, ``accuracy``, ``simulation``, ``mpc``, ``loop`` and ``seconds``
        (the benchmark's own wall time).
    """
    start = time.perf_counter()
    machine = _machine()
    sim = bench_sim(repeats=1 if quick else 3, duration=2.0 if quick else 10.0)
    mpc = mpc_benchmark(
        str(DEFAULT_MODEL),
        steps=40 if quick else 300,
        variants={"osqp_sparse": default_variants()["osqp_sparse"]},
        python_control_solves=1 if quick else 3,
        nmpc_steps=20 if quick else 100,
        nmpc_variants={"rti_frozen": default_nmpc_variants()["rti_frozen"]},
    )
    loop = bench_loop(repeats=1 if quick else 3)
    return {
        "machine": machine,
        "quick": quick,
        "accuracy": {"table3": _table3(), "rk4": sim["accuracy_at_scipy_span"]},
        "simulation": {
            k: sim[k]
            for k in (
                "realtime_factor_compiled",
                "ratio_vs_scipy",
                "realtime_factor_scipy",
                "fidelity",
                "dt",
            )
        },
        "mpc": _mpc_figures(mpc),
        "loop": {k: loop[k] for k in ("run_wall_s", "plant_only_s", "ratio")},
        "seconds": time.perf_counter() - start,
    }


def _mpc_figures(result: dict[str, Any]) -> dict[str, Any]:
    """Median and p95 solve (ms) of the sparse OSQP MPC, the NMPC and python-control."""
    sparse = result["variants"]["osqp_sparse"]["solve_ms"]
    out: dict[str, Any] = {
        "sample_time_ms": 1e3 * result["problem"]["sample_time_s"],
        "mpc_median_ms": sparse["median"],
        "mpc_p95_ms": sparse["p95"],
    }
    nmpc = result.get("nmpc", {}).get("rti_frozen")
    if nmpc:
        out["nmpc_median_ms"] = nmpc["step_ms"]["median"]
        out["nmpc_p95_ms"] = nmpc["step_ms"]["p95"]
    pc = result.get("python_control", {})
    if "ratio_median" in pc:
        out["python_control_ratio"] = pc["ratio_median"]
    return out


def markdown(result: dict[str, Any]) -> str:
    """The table the documentation includes: figure, value, the command that measures it.

    Parameters
    ----------
    result : dict
        :func:`headline`'s result, with a ``study`` entry (``runs``, ``workers``,
        ``runs_per_min``) where the study throughput was measured.

    Returns
    -------
    str
        A sentence naming the machine and date, and a Markdown table.
    """
    m, acc, sim, mpc, loop = (
        result[k] for k in ("machine", "accuracy", "simulation", "mpc", "loop")
    )
    rows = [
        (
            "Table 3 (Subedi et al. 2021), largest frequency error",
            f"{acc['table3']['max_abs_error_hz']:.4f} Hz over {acc['table3']['frequencies']}",
            "`flexctrl reproduce subedi`",
        ),
        (
            "joint angles after 1 s of free vibration (0.1 m tip deflection) against RK4 at "
            "0.1 ms: compiled RK4 at 1 ms / scipy RK45 (rtol 1e-8)",
            f"{acc['rk4']['max_q_error_rk4_dt_vs_rk4_dt_over_10']:.1e} / "
            f"{acc['rk4']['max_q_error_scipy_vs_rk4_dt_over_10']:.1e} rad",
            "`flexctrl bench sim`",
        ),
        (
            "simulation speed, three-link arm amm:2, RK4 1 ms",
            f"{sim['realtime_factor_compiled']:.0f}x real time, "
            f"{sim['ratio_vs_scipy']:.0f}x scipy solve_ivp",
            "`flexctrl bench sim`",
        ),
        (
            "linear MPC step (OSQP, warm), median / p95",
            f"{mpc['mpc_median_ms']:.2f} / {mpc['mpc_p95_ms']:.2f} ms "
            f"(sample {mpc['sample_time_ms']:.1f} ms)",
            "`flexctrl bench mpc`",
        ),
    ]
    if "nmpc_median_ms" in mpc:
        rows.append(
            (
                "NMPC real-time iteration, median / p95",
                f"{mpc['nmpc_median_ms']:.2f} / {mpc['nmpc_p95_ms']:.2f} ms",
                "`flexctrl bench mpc`",
            )
        )
    if "python_control_ratio" in mpc:
        rows.append(
            (
                "python-control create_mpc_iosystem on the same problem",
                f"{mpc['python_control_ratio']:.0f}x slower (median)",
                "`flexctrl bench mpc`",
            )
        )
    rows.append(
        (
            "closed-loop LQR run against the plant alone (warm)",
            f"{loop['ratio']:.2f}x ({1e3 * loop['run_wall_s']:.0f} ms)",
            "`flexctrl bench loop`",
        )
    )
    if "study" in result:
        study = result["study"]
        rows.append(
            (
                "quickstart study throughput",
                f"{study['runs_per_min']:.0f} runs/min ({study['runs']} runs, "
                f"{study['workers']} workers)",
                "`flexctrl study quickstart`",
            )
        )
    load = m["load_average_1min"]
    head = (
        f"Measured {m['date']} on {m['processor']} ({m['cpus']} CPUs, Python {m['python']}, "
        f"load average {load:.1f}) by `flexctrl bench all --markdown FILE`"
        + (" (quick mode)" if result.get("quick") else "")
        + "."
    )
    lines = [head, "", "| figure | value | measured by |", "|---|---|---|"]
    lines += [f"| {a} | {b} | {c} |" for a, b, c in rows]
    return "\n".join(lines) + "\n"
