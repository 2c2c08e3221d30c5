"""The payload-change scene with the fixed and the payload-aware controllers and the oracle.

``studies/scenes/payload_change.toml`` (joint 1 from 0 to 30 deg in 1.5 s, rest, the payload
steps at 3 s, back from 4 s, noise on, residual window 6.5-8 s) for each payload change:
``lqr`` and ``mpc`` designed at 2 kg, ``lqr_payload`` and ``mpc_payload`` told only 0-4 kg,
and the oracle (``lqr`` designed at the new payload, on a plant that carries it throughout).
Prints, per run: stable, the residual after the move back (mm), its ratio to the oracle's, and
for the payload-aware ones the estimate's error at the end (kg) and the time from which it
stays within 0.2 kg (s; the move back starts at 4 s).

Run: ``python benchmarks/payload_change.py [--changes 0:4 0:2 4:0 2:0] [--seed 1]``
"""

from __future__ import annotations

import argparse
import math

import flexctrl as fc

SCENE = "studies/scenes/payload_change.toml"
CONTROLLERS = ("lqr", "mpc", "lqr_payload", "mpc_payload")


def run(controller: str, sets: list[str]):
    """The scene with ``sets`` overrides and ``controller``; its metrics."""
    scene = fc.load_scene(SCENE, sets)
    return fc.run_scene(scene, controller=controller, on_divergence="record").metrics


def one_change(before: float, after: float, seed: int) -> list[str]:
    """Markdown rows for the change ``before -> after`` (kg)."""
    base = [f"payload={before}", f"payload_changes[1].mass={after}", f"noise.seed={seed}"]
    oracle_sets = [
        f"payload={after}",
        f"payload_changes[1].mass={after}",
        f"design_payload={after}",
        f"noise.seed={seed}",
    ]
    oracle = run("lqr", oracle_sets)
    rows = []
    for name in CONTROLLERS + ("oracle",):
        m = oracle if name == "oracle" else run(name, base)
        residual = m["tip_residual_rms"]
        ratio = residual / oracle["tip_residual_rms"] if math.isfinite(residual) else math.nan
        estimate = ""
        if "payload_estimate_time" in m:
            estimate = f"{m['payload_estimate_error']:.3f} kg, {m['payload_estimate_time']:.2f} s"
        rows.append(
            f"| {before:g} -> {after:g} kg | {name} | {int(m['stable'])} | "
            f"{1e3 * residual:.3f} | {ratio:.2f} | {estimate} |"
        )
        print(rows[-1], flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--changes", nargs="+", default=["0:4", "0:2", "4:0", "2:0"])
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    print(
        "| change | controller | stable | residual (mm) | / oracle | estimate error, within "
        "0.2 kg from |"
    )
    print("|---|---|---|---|---|---|")
    for change in args.changes:
        before, after = (float(v) for v in change.split(":"))
        one_change(before, after, args.seed)


if __name__ == "__main__":
    main()
