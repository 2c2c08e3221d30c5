"""The MPC benchmark: solve times of the linear MPC variants, python-control's MPC and the NMPC.

:func:`mpc_benchmark` returns a plain dict (JSON-serialisable) for the CLI and the report.
Scenario: the three-link arm (``amm:2``: 18 states, 3 inputs) at the target
equilibrium ``target_deg``, started ``offset_deg`` away, regulated for ``steps`` samples.
The linear MPC variants run against their own ZOH model (so every variant sees the
same states, and the timing is of the solver, not of a plant simulation); the NMPC
runs against the nonlinear RK4 shooting map.  Times:

``solve_ms``  the QP solver alone (OSQP ``info.run_time``; CasADi ``t_wall_total``/solver);
``step_ms``   the whole ``controller.step`` (estimation, update, solve, fallback logic).

Wall-clock figures depend on the machine and on what else runs on it; the dict
records the CPU count and load average.

Example
-------
``python -c "from flexctrl.bench.mpc_step import mpc_benchmark; import json;
print(json.dumps(mpc_benchmark(), indent=1))"``
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Sequence
from importlib.metadata import version
from typing import Any, cast

import control
import numpy as np

from flexctrl.bench.nmpc_step import default_nmpc_variants, ms_stats, nmpc_lines, nmpc_rows
from flexctrl.control import MPCController, design
from flexctrl.control.mpc.qp_backends import Solution
from flexctrl.linear import equilibrium
from flexctrl.scenes.model_files import load_model
from flexctrl.spec.mpc_settings import MPCSettings, OSQPSettings

COMMAND = (
    'python -c "from flexctrl.bench.mpc_step import mpc_benchmark; import json; '
    'print(json.dumps(mpc_benchmark(), indent=1))"'
)


def default_variants() -> dict[str, dict[str, Any]]:
    """Settings overrides per linear-MPC variant, on top of :class:`MPCSettings`.

    Returns
    -------
    dict
        Variant name -> keyword overrides of :class:`MPCSettings`.
    """
    return {
        "osqp_sparse": {},
        "osqp_sparse_ruiz": {"osqp": OSQPSettings(scaling=10)},
        "osqp_sparse_eps1e-4": {"osqp": OSQPSettings(eps_abs=1e-4, eps_rel=1e-4)},
        "osqp_sparse_cold": {"warm_start": "none"},
        "osqp_sparse_unscaled": {"scaling": "none", "osqp": OSQPSettings(scaling=10)},
        "osqp_condensed": {"formulation": "condensed", "osqp": OSQPSettings(scaling=10)},
        "hpipm_sparse": {"backend": "hpipm"},
        "daqp_condensed": {"formulation": "condensed", "backend": "daqp"},
    }


def _mpc(model, op, settings: MPCSettings) -> MPCController:
    """The linear MPC of ``settings`` (:func:`flexctrl.design` of MPC settings)."""
    return cast(MPCController, design(model, op, settings))


def _run_linear(model, op, settings, dx0: np.ndarray, steps: int) -> dict[str, Any]:
    """One linear-MPC variant regulating its own ZOH model for ``steps`` samples."""
    start = time.perf_counter()
    ctrl = _mpc(model, op, settings)
    build = time.perf_counter() - start
    ctrl.reset()
    Ad, Bd = ctrl.plant.Ad, ctrl.plant.Bd
    dx = dx0.copy()
    solve, iters = [], []
    for k in range(steps):
        u = ctrl.step(k * ctrl.sample_time, op.x + dx)
        last = cast(Solution, ctrl.last)  # every step solves a QP
        solve.append(last.solve_time)
        iters.append(last.iterations)
        dx = Ad @ dx + Bd @ (u - op.u)
    summary = ctrl.stats.summary()
    it = np.asarray(iters, dtype=float)
    iterations = {
        "median": float(np.median(it)),
        "p95": float(np.percentile(it, 95)),
        "max": float(it.max()),
    }
    return {
        "build_s": build,
        "first_solve_ms": float(solve[0] * 1e3),
        "solve_ms": ms_stats(solve[1:]),
        "step_ms": ms_stats(ctrl.stats.step_times[1:]),
        "iterations": iterations if np.all(it >= 0) else None,
        "status": summary["status"],
        "fallbacks": summary["fallbacks"],
        "slack_max_m": summary["slack_max"],
        "final_joint_error_deg": float(np.degrees(np.max(np.abs(dx[: model.n_u])))),
        "qp_size": {"variables": int(ctrl.qp.H.shape[0]), "rows": int(ctrl.qp.A.shape[0])},
    }


def _python_control(model, op, settings, dx0: np.ndarray, solves: int) -> dict[str, Any]:
    """python-control's ``create_mpc_iosystem`` on the same scaled problem (no soft rows)."""
    # python-control's optimal-control module, needed by this comparison alone
    import control.optimal as opt

    ctrl = _mpc(model, op, dataclasses.replace(settings, soft="none"))
    pb = ctrl.problem
    sysd = control.ss(pb.A, pb.B, np.eye(pb.n), 0, dt=ctrl.sample_time)
    timepts = np.arange(pb.horizon + 1) * ctrl.sample_time
    cost = opt.quadratic_cost(sysd, pb.Q, pb.R)
    terminal = opt.quadratic_cost(sysd, pb.P, None)
    constraints = [opt.input_range_constraint(sysd, pb.v_lo, pb.v_hi)]
    mpc = opt.create_mpc_iosystem(sysd, timepts, cost, constraints, terminal_cost=terminal)
    z = dx0 / pb.Sx
    guess = np.zeros(mpc.nstates)
    times, moves = [], []
    for _ in range(solves):
        start = time.perf_counter()
        v = np.asarray(mpc.output(0.0, guess, z), dtype=float).ravel()
        times.append(time.perf_counter() - start)
        moves.append(v)
    # the same first move from our OSQP controller (tight tolerance) for the comparison
    tight_osqp = OSQPSettings(eps_abs=1e-8, eps_rel=1e-8, max_iter=20000, polishing=True)
    tight = design(model, op, dataclasses.replace(settings, soft="none", osqp=tight_osqp))
    tight.reset()
    u = tight.step(0.0, op.x + dx0)
    v_ours = (u - op.u) / pb.Su
    return {
        "solve_s": [float(t) for t in times],
        "median_s": float(np.median(times)),
        "first_move_difference": float(np.max(np.abs(moves[0] - v_ours))) if moves else math.nan,
        "method": "control.optimal.create_mpc_iosystem (scipy SLSQP), one output() call per solve",
    }


def _header(model, model_path, fidelity, base, steps, target_deg, offset_deg) -> dict[str, Any]:
    """The benchmark's problem and environment, and an empty table of variants."""
    return {
        "problem": {
            "model": str(model_path),
            "fidelity": fidelity,
            "states": model.n_x,
            "inputs": model.n_u,
            "horizon": base.horizon,
            "sample_time_s": base.sample_time,
            "steps": steps,
            "target_deg": list(target_deg),
            "offset_deg": list(offset_deg),
            "soft_constraint": f"{base.soft} <= {base.deflection_limit} m",
        },
        "environment": {
            "cpu_count": os.cpu_count(),
            "load_average": list(os.getloadavg()),
            "osqp": version("osqp"),
            "casadi": version("casadi"),
            "control": version("control"),
        },
        "variants": {},
        "command": COMMAND,
    }


def _linear_variants(model, op, base, dx0, steps, variants) -> dict[str, Any]:
    """Every linear-MPC variant's figures; a variant that cannot be built reports its error."""
    rows: dict[str, Any] = {}
    for name, overrides in variants.items():
        try:
            rows[name] = _run_linear(model, op, dataclasses.replace(base, **overrides), dx0, steps)
        except Exception as exc:  # a missing plugin must not sink the whole benchmark
            rows[name] = {"error": f"{type(exc).__name__}: {exc}"}
    return rows


def _python_control_row(model, op, base, dx0, steps, solves: int) -> dict[str, Any]:
    """python-control's solves, with the ratio of its median to OSQP's on the same problem."""
    pc = _python_control(model, op, base, dx0, solves)
    ours = _run_linear(model, op, dataclasses.replace(base, soft="none"), dx0, steps)
    pc["osqp_sparse_no_soft_solve_ms"] = ours["solve_ms"]
    pc["ratio_median"] = pc["median_s"] * 1e3 / ours["solve_ms"]["median"]
    return pc


def mpc_benchmark(
    model_path: str = "models/subedi3link.toml",
    *,
    fidelity: str = "amm:2",
    horizon: int = 20,
    sample_time: float = 0.01,
    steps: int = 300,
    target_deg: Sequence[float] = (80.0, -10.0, -10.0),
    offset_deg: Sequence[float] = (-6.0, 4.0, -4.0),
    variants: dict[str, dict[str, Any]] | None = None,
    python_control_solves: int = 1,
    nmpc: bool = True,
    nmpc_steps: int = 100,
    nmpc_variants: dict[str, dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """Run the MPC benchmark (see the module docstring) and return its figures.

    Parameters
    ----------
    model_path : str
        The arm's model file (a shipped name or a path).
    fidelity : str
        The model's fidelity.
    horizon : int
        MPC horizon, samples.
    sample_time : float
        Sample time, s.
    steps : int
        Closed-loop samples per linear-MPC variant.
    target_deg, offset_deg : sequence of float
        Target joint angles and the initial offset from them, degrees.
    variants : dict, optional
        Name -> :class:`MPCSettings` overrides (default :func:`default_variants`).
    python_control_solves : int
        Solves of python-control's MPC to time (0 skips it; each takes seconds).
    nmpc : bool
        Whether to time the NMPC.
    nmpc_steps : int
        Closed-loop samples per NMPC variant.
    nmpc_variants : dict, optional
        Name -> :class:`~flexctrl.spec.mpc_settings.NMPCSettings` overrides (default
        :func:`~flexctrl.bench.nmpc_step.default_nmpc_variants`).

    Returns
    -------
    dict
        ``problem``, ``environment``, ``variants`` (per variant: ``solve_ms`` and
        ``step_ms`` as median/p95/max, iterations, status counts, fallbacks),
        ``python_control`` (seconds per solve and the ratio to ``osqp_sparse``),
        ``nmpc`` (the variants stepped one sample each in turn), ``nmpc_blocks`` (the same
        runs in blocks of consecutive samples, :mod:`flexctrl.bench.nmpc_step`) and
        ``command``.
    """
    model = load_model(model_path, fidelity=fidelity)
    op = equilibrium(model, np.radians(np.asarray(target_deg, dtype=float)))
    dx0 = np.zeros(model.n_x)
    dx0[: model.n_u] = np.radians(np.asarray(offset_deg, dtype=float))
    base = MPCSettings(horizon=horizon, sample_time=sample_time)
    result = _header(model, model_path, fidelity, base, steps, target_deg, offset_deg)
    linear = variants if variants is not None else default_variants()
    result["variants"] = _linear_variants(model, op, base, dx0, steps, linear)
    if python_control_solves > 0:
        result["python_control"] = _python_control_row(
            model, op, base, dx0, steps, python_control_solves
        )
    if nmpc:
        nonlinear = nmpc_variants if nmpc_variants is not None else default_nmpc_variants()
        result.update(nmpc_rows(model, op, dx0, nmpc_steps, horizon, sample_time, nonlinear))
    return result


def format_benchmark(result: dict[str, Any]) -> str:
    """A short text table of :func:`mpc_benchmark`'s figures.

    Parameters
    ----------
    result : dict
        What :func:`mpc_benchmark` returned.

    Returns
    -------
    str
        One line per variant, times in ms.
    """
    problem, env = result["problem"], result["environment"]
    lines = [
        f"MPC benchmark: {problem['states']} states, {problem['inputs']} inputs, "
        f"N = {problem['horizon']}, dt = {problem['sample_time_s'] * 1e3:g} ms; "
        f"load {env['load_average'][0]:.2f} on {env['cpu_count']} CPUs",
        f"{'variant':24s} {'solve med':>10s} {'p95':>8s} {'max':>8s} {'step med':>9s} "
        f"{'iter med':>9s}  status",
    ]
    for name, v in result["variants"].items():
        if "error" in v:
            lines.append(f"{name:24s} {v['error']}")
            continue
        it = v["iterations"]["median"] if v["iterations"] else float("nan")
        solve = v["solve_ms"]
        lines.append(
            f"{name:24s} {solve['median']:10.3f} {solve['p95']:8.3f} {solve['max']:8.3f} "
            f"{v['step_ms']['median']:9.3f} {it:9.0f}  {v['status']}"
        )
    if "python_control" in result:
        pc = result["python_control"]
        lines.append(
            f"python-control MPC: {pc['median_s']:.2f} s per solve = {pc['ratio_median']:.0f} x "
            f"OSQP sparse (first moves differ by {pc['first_move_difference']:.1e} in scaled "
            "units)"
        )
    return "\n".join(lines + nmpc_lines(result))


__all__ = [
    "mpc_benchmark",
    "default_variants",
    "default_nmpc_variants",
    "format_benchmark",
    "COMMAND",
]
