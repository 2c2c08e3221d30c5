"""A loop of one's own (``fc.Plant`` + ``ctrl.step``) against ``fc.closed_loop``, side by side.

The scene of ``studies/scenes/move_joint1_30deg.toml`` from Python: the three-link arm
(``--fidelity``, 2 kg, horizontal, 0.5 % modal damping), a 30 degree quintic move of joint 1
in 1.5 s, run for ``--duration`` s with each controller.  Per round and controller,
interleaved: one ``fc.closed_loop`` run (its loop's wall time, ``meta["wall_time_s"]``) and
one own loop (``plant.output``, then ``ctrl.step`` and ``plant.step`` per sample, timed
around the loop), both at ``fc.closed_loop``'s default plant step, noise off.  Prints the
medians over the rounds per sample and the ratio own / closed_loop; "overhead" is the loop's
time less the controller's own steps (``ctrl.stats.step_times``): what the plant, the sensors
and the bookkeeping cost (a closed loop that chains a linear law in CasADi times only its
first step in Python, so its overhead there includes the law).  The largest joint-angle
difference of the two final states (deg) shows they ran the same loop.

    .venv/bin/python benchmarks/own_loop.py [--controllers lqr mpc] [--rounds 5]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

import flexctrl as fc


def own_loop(model, ctrl, move, duration: float, dt: float):
    """Run ``ctrl`` on a :class:`fc.Plant` of ``model``; ``(plant, loop wall s, steps s)``."""
    ctrl.set_reference(move)
    ctrl.reset()
    plant = fc.Plant.for_controller(model, ctrl, move.start, dt=dt)
    n = math.ceil(duration / ctrl.sample_time - 1e-9)
    start = time.perf_counter()
    y = plant.output()
    for _ in range(n):
        y = plant.step(ctrl.step(plant.time, y))
    wall = time.perf_counter() - start
    return plant, wall, float(np.sum(ctrl.stats.step_times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--controllers", nargs="+", default=["lqr", "mpc"])
    parser.add_argument("--fidelity", default="amm:2")
    parser.add_argument("--duration", type=float, default=4.0)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    model = fc.load_model(
        "subedi3link",
        payload=2.0,
        fidelity=args.fidelity,
        gravity=[0.0, 0.0],
        overrides=[f"links[{i}].damping_ratio=0.005" for i in (1, 2, 3)],
    )
    op = fc.equilibrium(model, np.radians([30.0, 0.0, 0.0]))
    move = fc.Move(start=np.zeros(3), target=np.radians([30.0, 0.0, 0.0]), time=1.5)
    print(f"{model.name} {args.fidelity}, {args.duration:g} s, medians of {args.rounds} rounds")
    header = "controller  samples  closed_loop us/sample  own us/sample  ratio"
    print(header + "  overhead closed/own us  overhead ratio  max |dq| deg")
    for name in args.controllers:
        ctrl = fc.design(model, op, fc.load_controller(name))
        rows = []
        for _ in range(args.rounds + 1):  # the first round compiles and loads: dropped
            res = fc.closed_loop(model, ctrl, move, args.duration)
            ref_wall = res.trajectory.meta["wall_time_s"]
            ref_steps = float(np.sum(ctrl.stats.step_times))
            plant, wall, steps = own_loop(model, ctrl, move, args.duration, plant_dt(res))
            diff = np.degrees(np.max(np.abs(plant.state[:3] - res.trajectory.states[-1][:3])))
            rows.append((ref_wall, wall, ref_wall - ref_steps, wall - steps, diff))
        rows = rows[1:]
        n = math.ceil(args.duration / ctrl.sample_time - 1e-9)
        med = [statistics.median(r[i] for r in rows) * 1e6 / n for i in range(4)]
        print(
            f"{name:<10}  {n:>7}  {med[0]:>21.1f}  {med[1]:>13.1f}  {med[1] / med[0]:>5.2f}"
            f"  {med[2]:>10.1f} / {med[3]:<9.1f}  {med[3] / med[2]:>14.2f}"
            f"  {max(r[4] for r in rows):.2e}"
        )


def plant_dt(result) -> float:
    """The plant step the closed loop ran at, s."""
    return float(result.trajectory.meta["dt"])


if __name__ == "__main__":
    main()
