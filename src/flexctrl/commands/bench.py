"""``flexctrl bench sim|mpc|loop|studies|runs``: simulation speed (:mod:`flexctrl.bench.simulation_speed`), MPC solve times (:mod:`flexctrl.bench.mpc_step`), closed-loop run against plant alone (:mod:`flexctrl.bench.loop_overhead`), study files side by side (:mod:`flexctrl.bench.studies`), one study's runs under two source trees (:mod:`flexctrl.bench.runs`)."""

from __future__ import annotations

import argparse
import json

from flexctrl.errors import SpecError

BENCHMARKS = ("sim", "mpc", "loop", "studies", "runs")


def add_parser(subparsers) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "bench",
        help="benchmarks: 'sim' measures RK4 (compiled and virtual machine) against scipy solve_ivp; "
        "'mpc' times linear MPC (OSQP and casadi QP backends), NMPC and python-control's MPC; "
        "'loop' times one whole closed-loop run against the plant's compiled simulation alone",
        description="'sim': simulated seconds per wall-clock second of a --duration RK4 run at 1 ms of the "
        "three-link arm (amm:2), compiled and in CasADi's virtual machine, beside scipy solve_ivp "
        "(RK45, rtol 1e-8) run for --scipy-span seconds and scaled; medians of --repeats runs. "
        "'mpc': the three-link arm (amm:2, 18 states, 3 inputs), horizon 20 at 10 ms: solve times "
        "(median, p95, max) of the warm-started linear MPC variants over --steps closed-loop samples, "
        "the NMPC real-time iteration, and python-control's create_mpc_iosystem on the same problem "
        "(--pc-solves solves; each takes seconds). "
        "'loop': one warm in-process closed-loop run of studies/scenes/move_joint1_30deg.toml (--controller, default "
        "the LQR), with a fresh design and with a fresh configuration, beside the plant's compiled RK4 simulation alone "
        "(same step and duration), interleaved --repeats rounds; prints run_wall_s, plant_only_s and their ratio. 'studies': --study files (default "
        "studies/quickstart_finest.toml and studies/quickstart_auto.toml) alternated, each in a fresh process run twice "
        "(first pass, repeated pass), --repeats rounds, with the --set overrides applied to every study; prints the "
        "pass times and their ratios to the first study (of the medians, and round by round for the first pass). "
        "'runs': the runs of one --study under two --tree source checkouts (one worker process each), alternated run "
        "by run; prints each tree's summed per-run wall time by --by and the ratio.",
    )
    parser.add_argument(
        "what",
        choices=BENCHMARKS,
        metavar="WHAT",
        help="benchmark to run: " + ", ".join(BENCHMARKS),
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument(
        "--repeats",
        type=int,
        default=3,
        metavar="N",
        help="runs per variant; medians are reported (default 3)",
    )
    parser.add_argument(
        "--model",
        default=None,
        metavar="MODEL",
        help="model file (default models/subedi3link.toml)",
    )
    parser.add_argument(
        "--fidelity", default="amm:2", metavar="F", help="model fidelity (default amm:2)"
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=10.0,
        metavar="S",
        help="simulated seconds per RK4 run (default 10)",
    )
    parser.add_argument(
        "--scipy-span",
        type=float,
        default=1.0,
        metavar="S",
        help="simulated seconds per scipy run (default 1; scaled)",
    )
    parser.add_argument(
        "--steps",
        type=int,
        default=300,
        metavar="N",
        help="mpc: closed-loop samples per variant (default 300)",
    )
    parser.add_argument(
        "--pc-solves",
        type=int,
        default=1,
        metavar="N",
        help="mpc: python-control solves to time (0 skips; default 1)",
    )
    parser.add_argument("--no-nmpc", action="store_true", help="mpc: skip the NMPC timing")
    parser.add_argument(
        "--controller",
        default=None,
        metavar="FILE",
        help="loop: controller file (default controllers/lqr.toml)",
    )
    parser.add_argument(
        "--study",
        action="append",
        default=None,
        metavar="FILE",
        help="studies: a study file (repeatable; the first is the baseline)",
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=0,
        metavar="N",
        help="studies: workers per pass (default 0: in the process)",
    )
    parser.add_argument(
        "--keep", default=None, metavar="DIR", help="studies: write the passes' folders here"
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="studies: override a key of every study file, as 'flexctrl study --set' (repeatable)",
    )
    parser.add_argument(
        "--tree",
        action="append",
        default=None,
        metavar="DIR",
        help="runs: a source checkout (twice: the old one first, then the new one)",
    )
    parser.add_argument(
        "--by", default="controller", metavar="COLUMN", help="runs: group wall times by this column"
    )
    parser.add_argument(
        "--exclude",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="runs: leave out the runs with this coordinate (repeatable), e.g. controller=nmpc",
    )
    parser.add_argument(
        "--use-cache",
        action="store_true",
        help="reuse the compiled-code cache (default: compile afresh to time it)",
    )
    return parser


def run(args: argparse.Namespace) -> int:
    if args.set and args.what != "studies":
        raise SpecError(
            f"value {args.set[0]!r} is not allowed for 'bench {args.what}'; allowed: --set with 'bench studies' only",
            key="--set",
        )
    if args.what == "mpc":
        return _run_mpc(args)
    if args.what == "loop":
        return _run_loop(args)
    if args.what == "studies":
        return _run_studies(args)
    if args.what == "runs":
        return _run_runs(args)
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
        f"flexctrl bench sim: {result['model']} ({result['fidelity']}, {result['n_states']} states), "
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
        f"  from CPU time: compiled {cpu['realtime_factor_compiled']:.1f}x, VM {cpu['realtime_factor_vm']:.1f}x, "
        f"scipy {cpu['realtime_factor_scipy']:.4f}x (1-min load average {result['load_average_1min']})"
    )
    print(
        f"  compiled / scipy = {result['ratio_vs_scipy']:.0f}; targets >= {result['targets']['realtime_factor_compiled']:g}x "
        f"and >= {result['targets']['ratio_vs_scipy']:g}x: {'met' if result['targets']['met'] else 'NOT met'}"
    )
    return 0


def _run_mpc(args: argparse.Namespace) -> int:
    from flexctrl.bench.mpc_step import format_benchmark, mpc_benchmark
    from flexctrl.bench.simulation_speed import DEFAULT_MODEL

    if args.steps < 2 or args.pc_solves < 0:
        raise SpecError(
            f"--steps {args.steps!r} / --pc-solves {args.pc_solves!r}; allowed: steps >= 2, solves >= 0",
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


def _run_studies(args: argparse.Namespace) -> int:
    from flexctrl.bench.studies import DEFAULT_STUDIES, bench_studies, format_studies

    if args.repeats < 1 or args.workers < 0:
        raise SpecError(
            f"value {min(args.repeats, args.workers)!r} is out of range; allowed: --repeats >= 1, --workers >= 0",
            key="--repeats",
        )
    from flexctrl.study.study_file import load_study

    for study in (
        args.study or DEFAULT_STUDIES
    ):  # a bad study or override is refused before any pass runs
        load_study(study, overrides=args.set)
    result = bench_studies(
        args.study or DEFAULT_STUDIES,
        rounds=args.repeats,
        workers=args.workers,
        keep=args.keep,
        overrides=args.set,
    )
    print(json.dumps(result, indent=2) if args.json else format_studies(result))
    return 0


def _run_runs(args: argparse.Namespace) -> int:
    from pathlib import Path

    from flexctrl.bench.runs import bench_runs, format_runs

    if not args.study or len(args.study) != 1 or not args.tree or len(args.tree) != 2:
        raise SpecError(
            f"--study {args.study!r} --tree {args.tree!r}; allowed: one --study FILE and two --tree DIR",
            key="--tree",
        )
    for tree in args.tree:
        if not (Path(tree) / "flexctrl" / "__init__.py").is_file():
            raise SpecError(
                f"value {tree!r} is not a flexctrl checkout; allowed: a folder holding flexctrl/__init__.py",
                key="--tree",
            )
    for item in args.exclude:
        if "=" not in item:
            raise SpecError(
                f"value {item!r} is not allowed; allowed: KEY=VALUE (a grid column and one of its values)",
                key="--exclude",
            )
    result = bench_runs(args.study[0], args.tree, by=args.by, exclude=args.exclude)
    print(json.dumps(result, indent=2) if args.json else format_runs(result))
    return 0
