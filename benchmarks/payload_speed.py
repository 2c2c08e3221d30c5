"""Wall time of the payload-aware controllers beside the fixed ones, on the move scene.

The LQR: the loop's wall time (``meta["wall_time_s"]``: the samples, not the design or the
reference tables) of ``controllers/lqr_payload.toml`` beside ``controllers/lqr.toml`` (8.5 ms)
and ``controllers/lqr_any_damping.toml`` (the same 2 ms recipe at one payload) on the
30-degree joint-1 move (amm:2, 4 kg plant, pose (0, 90) deg, noise on, 6 s), and the ratios.
The MPC pair: the median and 95th percentile of ``controller.step`` of ``mpc_payload.toml``
and ``mpc.toml`` on the same run, against ``mpc_payload.toml``'s sample time.  Set-up (grid,
QPs, reference tables) is printed apart.

Run: ``python benchmarks/payload_speed.py [repeats]``
"""

from __future__ import annotations

import sys
import time

import numpy as np

import flexctrl as fc

POSE = np.radians([30.0, 0.0, 90.0])
START = np.radians([0.0, 0.0, 90.0])
DAMPING = {f"links[{i}].damping_ratio": 0.005 for i in (1, 2, 3)}


def arm(payload: float):
    return fc.load_model(
        "subedi3link",
        payload=payload,
        fidelity="amm:2",
        gravity=[0.0, 0.0],
        overrides=DAMPING,
        reference_q=START,
    )


def run(name: str, model, plant, move):
    """Design (timed), one run to build the reference tables, then the timed run."""
    start = time.perf_counter()
    ctrl = fc.design(model, fc.equilibrium(model, POSE), fc.load_controller(name))
    fc.closed_loop(model, ctrl, move, 6.0, plant=plant, noise=1, on_divergence="record")
    setup = time.perf_counter() - start
    res = fc.closed_loop(model, ctrl, move, 6.0, plant=plant, noise=1, on_divergence="record")
    stats = ctrl.stats.summary()
    return res.trajectory.meta["wall_time_s"], stats["median_ms"], stats["p95_ms"], setup


def main(repeats: int = 3) -> None:
    model, plant = arm(2.0), arm(4.0)
    move = fc.Move(start=START, target=POSE, time=1.5)
    rows = {name: [] for name in ("lqr", "lqr_any_damping", "lqr_payload", "mpc", "mpc_payload")}
    for _ in range(repeats):
        for name in rows:
            rows[name].append(run(name, model, plant, move))
    best = {name: np.min(np.array(r), axis=0) for name, r in rows.items()}
    for name, (wall, median, p95, setup) in best.items():
        print(
            f"{name:12s} run {wall:.3f} s  step median {median:.3f} ms  p95 {p95:.3f} ms  "
            f"set-up {setup:.1f} s"
        )
    wall = {name: b[0] for name, b in best.items()}
    print(
        f"LQR run-time ratio (payload-aware / fixed): {wall['lqr_payload'] / wall['lqr']:.2f} "
        f"against lqr, {wall['lqr_payload'] / wall['lqr_any_damping']:.2f} against lqr_any_damping"
    )
    sample_ms = 1e3 * fc.load_controller("mpc_payload").sample_time
    print(
        f"MPC median-step ratio (payload-aware / fixed): "
        f"{best['mpc_payload'][1] / best['mpc'][1]:.2f}; payload-aware p95 "
        f"{best['mpc_payload'][2]:.3f} ms against its {sample_ms:g} ms sample"
    )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 3)
