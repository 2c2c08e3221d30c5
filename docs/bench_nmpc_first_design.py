"""A worker's first NMPC design with its compiled linearisation found by recipe, against built, side by side.

Each round starts two fresh Python processes, one per path, alternated; each runs the NMPC
row of ``studies/payload_configuration_slice.toml`` at two poses in one process (as a pool
worker does) and prints the time of each ``design_nmpc`` call: the first pays the horizon
linearisation (built, or found on disk by its recipe), the second finds it in the
process.  Both paths load the same library from the disk cache, so run it once first to
fill the cache.

    .venv/bin/python docs/bench_nmpc_first_design.py [ROUNDS]
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

ONE_PROCESS = r"""
import functools, json, sys, time
import flexctrl.control.nmpc.controller as nmpc
from flexctrl.study.runner import run_study
from flexctrl.study.study_file import load_study

design, times = nmpc.design_nmpc, []

def timed(*args, **kwargs):
    start = time.perf_counter()
    result = design(*args, library_by_recipe=sys.argv[1] == "recipe", **kwargs)
    times.append(time.perf_counter() - start)
    return result

nmpc.design_nmpc = timed
spec = load_study("studies/payload_configuration_slice.toml",
                  overrides=['grid.controller=["../controllers/nmpc.toml"]', "grid.q2=[0]"])
run_study(spec, sys.argv[2], workers=0, progress="none", report=False)
print(json.dumps(times))
"""


def main(rounds: int = 3) -> None:
    results: dict[str, list[list[float]]] = {"recipe": [], "built": []}
    for _ in range(rounds):
        for path in ("recipe", "built"):
            with tempfile.TemporaryDirectory() as out:
                done = subprocess.run(
                    [sys.executable, "-c", ONE_PROCESS, path, str(Path(out) / "study")],
                    cwd=ROOT,
                    capture_output=True,
                    text=True,
                    check=True,
                )
            results[path].append(json.loads(done.stdout.strip().splitlines()[-1]))
    print(
        f"load average {os.getloadavg()[0]:.2f}; design_nmpc (s) per process: first pose, second pose"
    )
    for path, runs in results.items():
        firsts = [r[0] for r in runs]
        print(
            f"  {path:6s} first {', '.join(f'{t:.3f}' for t in firsts)} (median {statistics.median(firsts):.3f}); "
            f"second {', '.join(f'{r[1]:.3f}' for r in runs)}"
        )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 3)
