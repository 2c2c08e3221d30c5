"""The NMPC part of the MPC benchmark: NMPC variants stepped interleaved and in blocks.

Each variant regulates its own copy of the nonlinear plant (the design model's RK4 map) from
the same start; :func:`nmpc_rows` gives the NMPC keys of
:func:`flexctrl.bench.mpc_step.mpc_benchmark`'s result and :func:`nmpc_lines` their text.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any, cast

import numpy as np

from flexctrl.control import NMPCController, design
from flexctrl.control.lqr import build_sensors, linear_plant
from flexctrl.control.nmpc import auto_substeps, interval_functions
from flexctrl.spec.controller_shared import SensorSettings
from flexctrl.spec.mpc_settings import NMPCSettings


def ms_stats(values_s: Sequence[float]) -> dict[str, float]:
    """Median, 95th percentile and maximum (ms) of the finite ``values_s`` (s).

    Parameters
    ----------
    values_s : sequence of float
        Times, s; NaN and infinite ones are left out.

    Returns
    -------
    dict
        ``{"median", "p95", "max"}`` in ms (NaN when no time is finite).
    """
    a = np.asarray(values_s, dtype=float) * 1e3
    a = a[np.isfinite(a)]
    if not a.size:
        return {"median": math.nan, "p95": math.nan, "max": math.nan}
    return {
        "median": float(np.median(a)),
        "p95": float(np.percentile(a, 95)),
        "max": float(a.max()),
    }


def default_nmpc_variants() -> dict[str, dict[str, Any]]:
    """NMPC variants (overrides of :class:`NMPCSettings`), stepped interleaved.

    ``rti_frozen`` is the shipped setting (``controllers/nmpc.toml``): one Jacobian of ``f``
    per sample, at the middle RK4 node of the horizon's middle interval, held over the whole
    horizon (``sensitivities = "midpoint"``, ``stages_per_jacobian = 20``), HPIPM warm-started
    from the shifted previous solution, predicting with the joints and the three slowest
    coupled modes at the target, the estimate's fast modes removed (12 states, 2 RK4
    substeps).  Against it, one setting changed each: ``rti_frozen_per_interval`` one Jacobian
    per interval of the horizon; ``rti_frozen_per_step`` one Jacobian per RK4 step at its start
    (``sensitivities = "frozen"``).  The others predict with the whole design model (18 states,
    9 substeps): ``rti_frozen_full`` (``controllers/nmpc_full.toml``); ``rti_frozen_cold`` with
    HPIPM's default start; ``rti_exact`` cold with exact sensitivities; ``rti_frozen_every3``
    one Jacobian of ``f`` per three RK4 steps.  ``rti_first_modes`` predicts with the first
    assumed mode of every link, the estimate selected (12 states, 2 substeps).

    Returns
    -------
    dict
        Variant name -> keyword overrides of :class:`NMPCSettings`.
    """
    reduced = {"prediction_modes": 1, "qp_warm_start": True}
    per_interval = {**reduced, "prediction_basis": "coupled", "prediction_map": "modal"}
    shipped = {**per_interval, "stages_per_jacobian": 20}
    return {
        "rti_frozen": {**shipped, "sensitivities": "midpoint"},
        "rti_frozen_per_interval": {**per_interval, "sensitivities": "midpoint"},
        "rti_frozen_per_step": {**per_interval},
        "rti_frozen_full": {"qp_warm_start": True},
        "rti_frozen_cold": {},
        "rti_exact": {"sensitivities": "exact"},
        "rti_frozen_every3": {"qp_warm_start": True, "jacobian_every": 3},
        "rti_first_modes": {**reduced, "prediction_basis": "assumed", "prediction_map": "select"},
    }


def _design_nmpcs(
    model, op, horizon: int, sample_time: float, variants: dict[str, dict[str, Any]]
) -> tuple[dict[str, NMPCController], dict[str, float]]:
    """Every variant's controller, and its design time (s)."""
    controllers, builds = {}, {}
    for name, overrides in variants.items():
        start = time.perf_counter()
        settings = NMPCSettings(horizon=horizon, sample_time=sample_time, **overrides)
        controllers[name] = cast(NMPCController, design(model, op, settings))
        builds[name] = time.perf_counter() - start
    return controllers, builds


def _run_nmpcs(
    model,
    op,
    dx0: np.ndarray,
    steps: int,
    horizon: int,
    sample_time: float,
    variants: dict[str, dict[str, Any]],
    block_rounds: int = 3,
) -> dict[str, Any]:
    """Every NMPC variant against its own copy of the nonlinear plant, per sample and in blocks.

    ``"sample"``: one sample of each variant in turn.  Interleaving puts the variants under
    the same load (the machine may be shared), so their ratios are meaningful even when the
    absolute times are not; but every call then finds the caches full of the other
    variants' code and data (one compiled linearization per variant).
    ``"block"``: the same runs again from the start (each controller reset), in
    ``block_rounds`` rounds of ``steps / block_rounds`` consecutive samples per variant, the
    order of the variants rotated every round: what a controller that runs alone sees (as in
    a study), with the load still shared at the scale of a block.  Each variant has its own
    plant, so the order changes no number but the times.  The plant is the design model's
    RK4 map with the substeps its own fastest mode needs (whatever model a variant
    predicts with).
    """
    plant_substeps = auto_substeps(
        linear_plant(model, op, build_sensors(model, SensorSettings(), op), sample_time)
    )
    F, _ = interval_functions(model, sample_time, plant_substeps, None)
    controllers, builds = _design_nmpcs(model, op, horizon, sample_time, variants)

    def run(schedule: list[tuple[str, range]]) -> dict[str, Any]:
        for ctrl in controllers.values():
            ctrl.reset()
        states = {name: op.x + dx0 for name in variants}
        cpu: dict[str, list[float]] = {name: [] for name in variants}
        for name, samples in schedule:
            ctrl = controllers[name]
            for k in samples:
                start = time.thread_time()
                u = ctrl.step(k * ctrl.sample_time, states[name])
                cpu[name].append(time.thread_time() - start)
                states[name] = np.array(F(states[name], u), dtype=float).ravel()
        return {
            name: _nmpc_summary(
                ctrl, variants[name], builds[name], cpu[name], states[name], op, model.n_u
            )
            for name, ctrl in controllers.items()
        }

    names = list(variants)
    per_sample = [(name, range(k, k + 1)) for k in range(steps) for name in names]
    size = -(-steps // block_rounds)
    blocks = [
        (names[(i + r) % len(names)], range(r * size, min(steps, (r + 1) * size)))
        for r in range(block_rounds)
        for i in range(len(names))
    ]
    return {
        "sample": run(per_sample),
        "block": run(blocks),
        "plant_substeps": plant_substeps,
        "block_rounds": block_rounds,
    }


def _nmpc_summary(
    ctrl, settings: dict, build_s: float, cpu: list[float], state: np.ndarray, op, n_u: int
) -> dict:
    """The figures of one NMPC variant's run (the first sample, a rollout's, left out)."""
    summary = ctrl.stats.summary()
    it = np.asarray(ctrl.stats.iterations[1:], dtype=float)
    return {
        "settings": settings,
        "build_s": build_s,
        "compiled": ctrl.compiled,
        "prediction_states": int(ctrl.problem.n),
        "substeps": ctrl.substeps,
        "step_ms": ms_stats(ctrl.stats.step_times[1:]),
        "step_cpu_ms": ms_stats(cpu[1:]),
        "linearize_and_assemble_ms": ms_stats(ctrl.timing["linearize_qp"][1:]),
        "qp_ms": ms_stats(ctrl.timing["qp"][1:]),
        "qp_iterations_median": float(np.median(it)) if it.size else math.nan,
        "status": summary["status"],
        "fallbacks": summary["fallbacks"],
        "final_joint_error_deg": float(np.degrees(np.max(np.abs((state - op.x)[:n_u])))),
    }


def nmpc_rows(model, op, dx0, steps, horizon, sample_time, variants) -> dict[str, Any]:
    """The NMPC keys of the benchmark's result: both schedules' figures and the speed-up.

    Parameters
    ----------
    model, op
        The design model and the target equilibrium.
    dx0 : ndarray
        The start's deviation from the target.
    steps : int
        Samples per variant.
    horizon : int
        Shooting intervals.
    sample_time : float
        s.
    variants : dict
        Name -> :class:`NMPCSettings` overrides.

    Returns
    -------
    dict
        ``nmpc_plant_substeps``, ``nmpc`` (interleaved), ``nmpc_blocks``,
        ``nmpc_block_rounds`` and, with ``rti_frozen`` and ``rti_frozen_full`` among the
        variants, ``nmpc_speedup``.
    """
    runs = _run_nmpcs(model, op, dx0, steps, horizon, sample_time, variants)
    rows: dict[str, Any] = {
        "nmpc_plant_substeps": runs["plant_substeps"],
        "nmpc": runs["sample"],
        "nmpc_blocks": runs["block"],
        "nmpc_block_rounds": runs["block_rounds"],
    }
    if "rti_frozen" in runs["sample"] and "rti_frozen_full" in runs["sample"]:
        fast, full = runs["sample"]["rti_frozen"], runs["sample"]["rti_frozen_full"]
        rows["nmpc_speedup"] = {
            "against": "rti_frozen_full",
            "step_median": full["step_ms"]["median"] / fast["step_ms"]["median"],
            "step_cpu_median": full["step_cpu_ms"]["median"] / fast["step_cpu_ms"]["median"],
        }
    return rows


def nmpc_lines(result: dict[str, Any]) -> list[str]:
    """The text lines of the NMPC variants (in blocks, then interleaved) and the speed-up.

    Parameters
    ----------
    result : dict
        :func:`flexctrl.bench.mpc_step.mpc_benchmark`'s result.

    Returns
    -------
    list of str
    """
    lines = []
    for name, v in result.get("nmpc", {}).items():
        block = result.get("nmpc_blocks", {}).get(name)
        if block:
            lines.append(
                f"NMPC {name} in blocks of consecutive samples: step median "
                f"{block['step_ms']['median']:.2f} ms, p95 {block['step_ms']['p95']:.2f} "
                f"(linearise+assemble {block['linearize_and_assemble_ms']['median']:.2f}, "
                f"QP {block['qp_ms']['median']:.2f})"
            )
        lines.append(
            f"NMPC {name}: step median {v['step_ms']['median']:.2f} ms, "
            f"p95 {v['step_ms']['p95']:.2f}, max {v['step_ms']['max']:.2f}, "
            f"CPU median {v['step_cpu_ms']['median']:.2f} "
            f"(linearise+assemble {v['linearize_and_assemble_ms']['median']:.2f}, "
            f"QP {v['qp_ms']['median']:.2f}, {v['qp_iterations_median']:.0f} iterations; "
            f"{v['prediction_states']} states, {v['substeps']} RK4 substeps, "
            f"compiled {v['compiled']})"
        )
    if "nmpc_speedup" in result:
        sp = result["nmpc_speedup"]
        lines.append(
            f"NMPC rti_frozen against {sp['against']} (interleaved): {sp['step_median']:.2f}x "
            f"faster by the median step, {sp['step_cpu_median']:.2f}x by CPU time"
        )
    return lines


__all__ = ["default_nmpc_variants", "nmpc_rows", "nmpc_lines", "ms_stats"]
