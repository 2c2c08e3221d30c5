"""The kept Jacobian of each rung built on the SX graph against the MX graph, side by side.

Each round starts one fresh Python process per graph (alternated, so both see the same
machine); each builds the three-link arm's ``rigid`` and ``amm:1..5`` models at one pose
and times the first ``jacobian_function(..., shared=True)`` of each (the build a process
pays once per structure), then evaluates it at three random states.  Printed: the median
build time per rung and graph, their ratio, whether the two graphs gave the same bits and the
largest difference between their values.

    .venv/bin/python docs/bench_jacobians.py [ROUNDS]
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RUNGS = ("rigid", "amm:1", "amm:2", "amm:3", "amm:4", "amm:5")

ONE_PROCESS = r"""
import json, sys, time
import numpy as np
import flexctrl as fc
from flexctrl.dynamics.build import build_model
from flexctrl.dynamics.jacobians import jacobian_function
graph, rungs = sys.argv[1], sys.argv[2].split(",")
arm = fc.load_arm(sys.argv[3])
out = {}
for rung in rungs:
    model = build_model(arm, rung, reference_q=[0.0, 1.2, -0.7])
    start = time.perf_counter()
    fun = jacobian_function(model, inputs=True, shared=True, graph=graph)  # as the Linearizer asks
    built = time.perf_counter() - start
    rng = np.random.default_rng(0)
    values = [[np.array(m, dtype=float).tolist() for m in fun(rng.uniform(-0.2, 0.2, model.n_x),
                                                               rng.uniform(-5, 5, model.n_u))] for _ in range(3)]
    out[rung] = {"build_s": built, "values": values}
print(json.dumps(out))
"""


def one(graph: str) -> dict:
    """One fresh process building every rung's kept Jacobian on ``graph``."""
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            ONE_PROCESS,
            graph,
            ",".join(RUNGS),
            str(ROOT / "models" / "subedi3link.toml"),
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(done.stdout)


def main(rounds: int = 3) -> None:
    times = {graph: {rung: [] for rung in RUNGS} for graph in ("sx", "mx")}
    same = {rung: True for rung in RUNGS}
    largest = {rung: 0.0 for rung in RUNGS}
    for _ in range(rounds):
        got = {graph: one(graph) for graph in ("sx", "mx")}
        for rung in RUNGS:
            for graph in ("sx", "mx"):
                times[graph][rung].append(got[graph][rung]["build_s"])
            same[rung] &= got["sx"][rung]["values"] == got["mx"][rung]["values"]
            for sx, mx in zip(got["sx"][rung]["values"], got["mx"][rung]["values"]):
                largest[rung] = max(
                    [largest[rung]]
                    + [float(np.max(np.abs(np.subtract(a, b)))) for a, b in zip(sx, mx)]
                )
    print(
        f"{'rung':<7} {'sx build (s)':>13} {'mx build (s)':>13} {'mx / sx':>8}  same bits  largest difference"
    )
    for rung in RUNGS:
        sx, mx = statistics.median(times["sx"][rung]), statistics.median(times["mx"][rung])
        print(
            f"{rung:<7} {sx:13.3f} {mx:13.3f} {mx / sx:8.2f}  {str(same[rung]):<9}  {largest[rung]:.1e}"
        )
    total_sx = sum(statistics.median(v) for v in times["sx"].values())
    total_mx = sum(statistics.median(v) for v in times["mx"].values())
    print(
        f"{'all':<7} {total_sx:13.3f} {total_mx:13.3f} {total_mx / total_sx:8.2f}  ({rounds} rounds, medians)"
    )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 3)
