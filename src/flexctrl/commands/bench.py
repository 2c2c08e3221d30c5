"""``flexctrl bench sim|mpc|loop``: the speed figures a user asks for.

Simulation speed (:mod:`flexctrl.bench.simulation_speed`), MPC solve times
(:mod:`flexctrl.bench.mpc_step`) and a closed-loop run against the plant alone
(:mod:`flexctrl.bench.loop_overhead`). Comparisons of the toolkit against an earlier
commit live beside the package, in ``benchmarks/``.
"""

from __future__ import annotations

import argparse
import json

from flexctrl.errors import SpecError

BENCHMARKS = ("sim", "mpc", "loop")


HELP = (
    "benchmarks: 'sim' measures RK4 (compiled and virtual machine) against scipy solve_ivp; "
    "'mpc' times linear MPC (OSQP and casadi QP backends), NMPC and python-control's MPC; "
    "'loop' times one whole closed-loop run against the plant's compiled simulation alone"
)
DESCRIPTION = (
    "'sim': simulated seconds per wall-clock second of a --duration RK4 run at 1 ms of the "
    "three-link arm (amm:2), compiled and in CasADi's virtual machine, beside scipy solve_ivp "
    "(RK45, rtol 1e-8) run for --scipy-span seconds and scaled; medians of --repeats runs. "
    "'mpc': the three-link arm (amm:2, 18 states, 3 inputs), horizon 20 at 10 ms: solve times "
    "(median, p95, max) of the warm-started linear MPC variants over --steps closed-loop "
    "samples, the NMPC real-time iteration, and python-control's create_mpc_iosystem on the "
    "same problem (--pc-solves solves; each takes seconds). 'loop': one warm in-process "
    "closed-loop run of studies/scenes/move_joint1_30deg.toml (--controller, default the LQR), "
    "beside the plant's compiled RK4 "
    "simulation alone (same step and duration), interleaved --repeats rounds; prints "
    "run_wall_s, plant_only_s and their ratio."
)
#: ``(flag, type, default, metavar, help)`` of the numeric and file options.
OPTIONS = (
    ("--repeats", int, 3, "N", "runs per variant; medians are reported (default 3)"),
    ("--model", str, None, "MODEL", "model file (default models/subedi3link.toml)"),
    ("--fidelity", str, "amm:2", "F", "model fidelity (default amm:2)"),
    ("--duration", float, 10.0, "S", "simulated seconds per RK4 run (default 10)"),
    ("--scipy-span", float, 1.0, "S", "simulated seconds per scipy run (default 1; scaled)"),
    ("--steps", int, 300, "N", "mpc: closed-loop samples per variant (default 300)"),
    ("--pc-solves", int, 1, "N", "mpc: python-control solves to time (0 skips; default 1)"),
    ("--controller", str, None, "FILE", "loop: controller file (default controllers/lqr.toml)"),
)


def add_parser(subparsers) -> argparse.ArgumentParser:
    """The ``bench`` sub-command's arguments."""
    parser = subparsers.add_parser("bench", help=HELP, description=DESCRIPTION)
    parser.add_argument(
        "what",
        choices=BENCHMARKS,
        metavar="WHAT",
        help="benchmark to run: " + ", ".join(BENCHMARKS),
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    for flag, kind, default, metavar, text in OPTIONS:
        parser.add_argument(flag, type=kind, default=default, metavar=metavar, help=text)
    parser.add_argument("--no-nmpc", action="store_true", help="mpc: skip the NMPC timing")
    parser.add_argument(
        "--use-cache",
        action="store_true",
        help="reuse the compiled-code cache (default: compile afresh to time it)",
    )
    return parser


def run(args: argparse.Namespace) -> int:
    if args.what == "mpc":
        return _run_mpc(args)
    if args.what == "loop":
        return _run_loop(args)
    from flexctrl.bench.simulation_speed import DEFAULT_MODEL, bench_sim

    if args.repeats < 1:
        raise SpecError(
            f"value {args.repeats!r} is out of range; allowed: an integer >= 1", key="--repeats"
        )
    for key, value in (("--duration", args.duration), ("--scipy-span", args.scipy_span)):
        if not value > 0:
            raise SpecError(f"value {value!r} is out of range; allowed: a number > 0 (s)", key=key)
    result = bench_sim(
        args.model or DEFAULT_MODEL,
        fidelity=args.fidelity,
        duration=args.duration,
        repeats=args.repeats,
        scipy_span=args.scipy_span,
        use_cache=args.use_cache,
    )
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(
        f"flexctrl bench sim: {result['model']} ({result['fidelity']}, {result['n_states']} "
        "states), "
        f"RK4 dt = {result['dt']:g} s, medians of {result['repeats']} runs"
    )
    print(
        f"  compiled RK4   {result['realtime_factor_compiled']:9.1f}x real time "
        f"({result['duration_s']:g} s runs; compile {result['compile_time_s']:.2f} s, flags {' '.join(result['flags'])})"
    )
    print(f"  VM RK4         {result['realtime_factor_vm']:9.1f}x real time")
    sp = result["scipy"]
    print(
        f"  scipy {sp['method']:8s} {result['realtime_factor_scipy']:9.4f}x real time "
        f"(rtol {sp['rtol']:g}, {sp['span_s']:g} s runs, scaled)"
    )
    cpu = result["cpu_time_based"]
    print(
        f"  from CPU time: compiled {cpu['realtime_factor_compiled']:.1f}x, VM "
        f"{cpu['realtime_factor_vm']:.1f}x, "
        f"scipy {cpu['realtime_factor_scipy']:.4f}x (1-min load average {result['load_average_1min']})"
    )
    print(
        f"  compiled / scipy = {result['ratio_vs_scipy']:.0f}; targets >= "
        f"{result['targets']['realtime_factor_compiled']:g}x "
        f"and >= {result['targets']['ratio_vs_scipy']:g}x: {'met' if result['targets']['met'] else 'NOT met'}"
    )
    return 0


def _run_mpc(args: argparse.Namespace) -> int:
    from flexctrl.bench.mpc_step import format_benchmark, mpc_benchmark
    from flexctrl.bench.simulation_speed import DEFAULT_MODEL

    if args.steps < 2 or args.pc_solves < 0:
        raise SpecError(
            f"--steps {args.steps!r} / --pc-solves {args.pc_solves!r}; allowed: steps >= 2, "
            "solves >= 0",
            key="--steps",
        )
    result = mpc_benchmark(
        str(args.model or DEFAULT_MODEL),
        fidelity=args.fidelity,
        steps=args.steps,
        python_control_solves=args.pc_solves,
        nmpc=not args.no_nmpc,
    )
    sparse = result["variants"].get("osqp_sparse", {})
    result["median_solve_s"] = sparse["solve_ms"]["median"] * 1e-3 if "solve_ms" in sparse else None
    result["p95_solve_s"] = sparse["solve_ms"]["p95"] * 1e-3 if "solve_ms" in sparse else None
    result["max_solve_s"] = sparse["solve_ms"]["max"] * 1e-3 if "solve_ms" in sparse else None
    result["ratio_vs_python_control"] = result.get("python_control", {}).get("ratio_median")
    if args.json:
        print(json.dumps(result, indent=2, default=str))
    else:
        print(format_benchmark(result))
    return 0


def _run_loop(args: argparse.Namespace) -> int:
    from flexctrl.bench.loop_overhead import DEFAULT_CONTROLLER, bench_loop, format_loop

    if args.repeats < 1:
        raise SpecError(
            f"value {args.repeats!r} is out of range; allowed: an integer >= 1", key="--repeats"
        )
    result = bench_loop(controller=args.controller or DEFAULT_CONTROLLER, repeats=args.repeats)
    print(json.dumps(result, indent=2) if args.json else format_loop(result))
    return 0
