"""Simulation speed: compiled RK4, RK4 in CasADi's virtual machine, and
``scipy.integrate.solve_ivp``.

The workload is the free-vibration scene of Subedi et al. (2021), Section 4.3
(three-link arm, two assumed modes per link, 2 kg payload, gravity on, link 3
deformed by q_f31 = 0.1 m, q_f32 = 0.002 m), simulated at dt = 1 ms.

* ``realtime_factor_compiled``: simulated seconds per wall-clock second of a
  ``duration`` (10 s) RK4 run through the compiled loop, outputs (energies, tip,
  deflections) included, compilation excluded (reported as ``compile_time_s``,
  measured in a fresh cache folder unless ``use_cache``);
* ``realtime_factor_vm``: the same run with ``compile=False``;
* ``realtime_factor_scipy``: ``solve_ivp`` RK45 at rtol 1e-8, atol 1e-10 with
  dense output on the same 1 ms grid, run for ``scipy_span`` seconds (1 s by
  default: it is more than 1000 times slower) and scaled, i.e. the factor is
  ``scipy_span / wall``;
* ``ratio_vs_scipy``: compiled over scipy.

Every factor is the median over ``repeats`` runs, from wall-clock time; the same
figures from process CPU time are given under ``cpu_time_based`` (on a shared
machine the wall-clock figures drop with the load, reported as
``load_average_1min``).
"""

from __future__ import annotations

import math
import platform
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.spec.shipped import data_root

REPO = data_root()
DEFAULT_MODEL = REPO / "models" / "subedi3link.toml"
TARGET_REALTIME = 200.0
TARGET_RATIO = 50.0


def _load_average() -> float | None:
    try:
        import os

        return os.getloadavg()[0]
    except (AttributeError, OSError):
        return None


def free_vibration_state(model) -> np.ndarray:
    """Rest at q = 0 with q_f31 = 0.1 m and q_f32 = 0.002 m (where the model has them)."""
    x0 = np.zeros(model.n_x)
    for name, value in (("qf31", 0.1), ("qf32", 0.002)):
        if name in model.coordinate_names:
            x0[model.coordinate_names.index(name)] = value
    return x0


def _measure(model, dt, duration, repeats, scipy_span, scipy_options, use_cache) -> dict:
    """Wall and CPU times of compiled RK4, RK4 in the VM and scipy, and the accuracy runs."""
    from flexctrl.sim import RK4, ScipyIntegrator

    x0 = free_vibration_state(model)
    with tempfile.TemporaryDirectory(prefix="flexctrl-bench-") as tmp:
        cache = None if use_cache else tmp
        compiled = RK4(model, dt, compile=True, cache_dir=cache).setup()
        metas_c = [compiled.run(x0, duration).meta for _ in range(repeats)]
        settings = compiled.settings()
        # accuracy reference for the scipy span: RK4 at dt/10 (same library: h is an input)
        coarse = compiled.run(x0, scipy_span)
        fine = RK4(model, dt / 10, compile=True, cache_dir=cache).run(x0, scipy_span)
    vm = RK4(model, dt, compile=False).setup()
    metas_vm = [vm.run(x0, duration).meta for _ in range(repeats)]
    sp = ScipyIntegrator(model, dt, **scipy_options).setup()
    metas_sp = []
    for _ in range(repeats):
        traj_sp = sp.run(x0, scipy_span)
        metas_sp.append(traj_sp.meta)
    return {
        "walls": [[m["wall_time_s"] for m in ms] for ms in (metas_c, metas_vm, metas_sp)],
        "cpus": [[m["cpu_time_s"] for m in ms] for ms in (metas_c, metas_vm, metas_sp)],
        "settings": settings,
        "coarse": coarse,
        "fine": fine,
        "scipy_run": traj_sp,
        "nfev": traj_sp.meta["counters"].get("rhs_evaluations", 0),
    }


def _accuracy(m: dict[str, Any], q: slice) -> dict[str, float]:
    """Joint-angle errors (rad) at the end of the scipy span against RK4 at a tenth of the step."""
    fine = m["fine"].states[-1, q]
    return {
        "max_q_error_rk4_dt_vs_rk4_dt_over_10": float(
            np.max(np.abs(m["coarse"].states[-1, q] - fine))
        ),
        "max_q_error_scipy_vs_rk4_dt_over_10": float(
            np.max(np.abs(m["scipy_run"].states[-1, q] - fine))
        ),
    }


def _host() -> dict[str, Any]:
    """The machine the figures are measured on."""
    return {
        "machine": platform.machine(),
        "processor": platform.processor() or None,
        "python": platform.python_version(),
    }


def bench_sim(
    model_path: str | Path = DEFAULT_MODEL,
    *,
    fidelity: str = "amm:2",
    payload: float = 2.0,
    duration: float = 10.0,
    dt: float = 1e-3,
    repeats: int = 3,
    scipy_span: float = 1.0,
    scipy_method: str = "RK45",
    scipy_rtol: float = 1e-8,
    scipy_atol: float = 1e-10,
    use_cache: bool = False,
) -> dict[str, Any]:
    """Measure the simulation speeds described in the module docstring; returns a dict."""
    from flexctrl.scenes.model_files import load_model

    start = time.perf_counter()
    model = load_model(model_path, payload=payload, fidelity=fidelity)
    build_time = time.perf_counter() - start
    scipy_options = dict(method=scipy_method, rtol=scipy_rtol, atol=scipy_atol)
    m = _measure(model, dt, duration, repeats, scipy_span, scipy_options, use_cache)
    walls_c, walls_vm, walls_sp = m["walls"]
    cpus_c, cpus_vm, cpus_sp = m["cpus"]
    settings, nfev = m["settings"], m["nfev"]
    rf_c = duration / statistics.median(walls_c)
    rf_vm = duration / statistics.median(walls_vm)
    rf_sp = scipy_span / statistics.median(walls_sp)
    return {
        "model": str(model_path),
        "fidelity": fidelity,
        "payload_kg": payload,
        "n_states": model.n_x,
        "dt": dt,
        "duration_s": duration,
        "repeats": repeats,
        "realtime_factor_compiled": rf_c,
        "realtime_factor_vm": rf_vm,
        "realtime_factor_scipy": rf_sp,
        "ratio_vs_scipy": rf_c / rf_sp,
        "ratio_compiled_vs_vm": rf_c / rf_vm,
        "cpu_time_based": {
            "realtime_factor_compiled": duration / statistics.median(cpus_c),
            "realtime_factor_vm": duration / statistics.median(cpus_vm),
            "realtime_factor_scipy": scipy_span / statistics.median(cpus_sp),
            "note": "process CPU time instead of wall time: less sensitive to other load on the "
            "machine",
        },
        "load_average_1min": _load_average(),
        "compile_time_s": settings["compile_time_s"],
        "compile_cache_hit": settings["cache_hit"],
        "compiled": settings["compiled"],
        "flags": settings["flags"],
        "model_build_time_s": build_time,
        "wall_times_compiled_s": walls_c,
        "wall_times_vm_s": walls_vm,
        "wall_times_scipy_s": walls_sp,
        "scipy": {
            "method": scipy_method,
            "rtol": scipy_rtol,
            "atol": scipy_atol,
            "span_s": scipy_span,
            "scaled": scipy_span != duration,
            "rhs_evaluations": nfev,
        },
        "accuracy_at_scipy_span": _accuracy(m, slice(0, model.n_q)),
        "targets": {
            "realtime_factor_compiled": TARGET_REALTIME,
            "ratio_vs_scipy": TARGET_RATIO,
            "met": bool(rf_c >= TARGET_REALTIME and rf_c / rf_sp >= TARGET_RATIO),
        },
        "host": _host(),
        "omega_max_rad_s": float(model.omega_max),
        "omega_max_dt": float(model.omega_max) * dt if math.isfinite(model.omega_max) else None,
    }
