"""The figures quoted in ``docs/explanation/finite-elements.md``: convergence tables, AMM-versus-FEM
comparison, timings.

Run ``python tools/fem_report.py --out out/fem`` (about 10 minutes; most
of it compiling and running the 16-element RK4 reference); ``--quick`` skips the
16-element runs.  Writes ``report.json`` and prints the tables.

Everything is computed, nothing is stored: locked-joint frequencies come from
:func:`flexctrl.dynamics.fem.fem_arm.locked_matrices` and the assumed-modes model's
``M`` and ``K`` (:mod:`flexctrl.dynamics.fem.locked_spectrum`); the bang-bang runs use a compiled
fixed-step RK4 (:func:`rk4_sampler`) with the step below the stability limit ``2.8 / omega_max``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from flexctrl.dynamics.fem.fem_arm import build_fem_model
from flexctrl.dynamics.fem.locked_spectrum import (
    free_joint_radius,
    locked_amm_hz,
    locked_fem_hz,
    rk4_step_for,
)
from flexctrl.spec.arm import ArmSpec, load_arm

__all__ = [
    "amm_versus_fem",
    "bangbang_runs",
    "free_joint_radius",
    "locked_amm_hz",
    "locked_convergence",
    "locked_fem_hz",
    "main",
    "rk4_sampler",
    "rk4_step_for",
    "timings",
]

CONFIGS_DEG = ((0.0, 0.0, 0.0), (0.0, 90.0, 0.0), (0.0, 45.0, -90.0))
PAYLOADS = (0.0, 2.0)


def locked_convergence(
    arm: ArmSpec, elements: Sequence[int] = (2, 4, 8, 16), reference: int = 32, n_modes: int = 6
) -> list[dict]:
    """Locked frequencies per N, eigenvalue errors against ``reference`` and observed orders."""
    rows = []
    for payload in PAYLOADS:
        a = arm.with_payload(payload)
        for q in CONFIGS_DEG:
            ref = locked_fem_hz(a, reference, q, n_modes)
            f = {N: locked_fem_hz(a, N, q, n_modes) for N in elements}
            err = {N: (f[N] ** 2 - ref**2) / ref**2 for N in elements}
            order = {
                f"{a_}-{b_}": np.log2(np.abs(err[a_]) / np.abs(err[b_])).tolist()
                for a_, b_ in zip(elements[:-1], elements[1:])
            }
            rows.append(
                {
                    "payload_kg": payload,
                    "q_deg": list(q),
                    "reference_N": reference,
                    "reference_hz": ref.tolist(),
                    "hz": {str(N): f[N].tolist() for N in elements},
                    "eigenvalue_rel_error": {str(N): err[N].tolist() for N in elements},
                    "observed_order": order,
                }
            )
    return rows


def amm_versus_fem(
    arm: ArmSpec, n_elements: int = 16, amm: Sequence[int] = (2, 4, 6), n_modes: int = 6
) -> list[dict]:
    """Locked frequencies of the assumed-modes model (2, 4, 6 modes per link) against FEM-N."""
    rows = []
    for payload in PAYLOADS:
        a = arm.with_payload(payload)
        for q in CONFIGS_DEG:
            fem = locked_fem_hz(a, n_elements, q, n_modes)
            row = {"payload_kg": payload, "q_deg": list(q), f"fem{n_elements}_hz": fem.tolist()}
            for k in amm:
                f = locked_amm_hz(a, k, q, n_modes)
                m = min(f.size, fem.size)
                row[f"amm{k}_hz"] = f.tolist()
                row[f"amm{k}_minus_fem_hz"] = (f[:m] - fem[:m]).tolist()
                row[f"amm{k}_rel"] = ((f[:m] - fem[:m]) / fem[:m]).tolist()
            rows.append(row)
    return rows


def rk4_sampler(
    model, substeps: int, h: float, chunk: int = 100, *, compile: bool = True
) -> Callable:
    """``run(x0, U) -> X``: ``substeps`` RK4 steps of ``h`` per sample, torque ``U[k]`` held per
    sample.

    The chained Function is compiled (cached) by :func:`flexctrl.sim.compile.compile_function`.
    Returns a callable and, as attribute ``compile_seconds``, the build time.
    """
    from flexctrl.sim.compile import compile_function
    from flexctrl.sim.rk4 import held_sample_loop

    loop = held_sample_loop(model, h, substeps, chunk, name=f"mapaccum_sample_{chunk}")
    start = time.perf_counter()
    compiled = compile_function(loop, enabled=compile)
    seconds = time.perf_counter() - start
    fun = compiled.function

    def run(x0: np.ndarray, U: np.ndarray) -> np.ndarray:
        n = U.shape[0]
        X = np.empty((n + 1, model.n_x))
        X[0] = x0
        for s in range(0, n, chunk):
            k = min(chunk, n - s)
            Uc = np.zeros((chunk, model.n_u))
            Uc[:k] = U[s : s + k]
            out = np.asarray(fun(X[s], Uc.T), dtype=float).T
            X[s + 1 : s + k + 1] = out[:k]
        return X

    run.compile_seconds = seconds  # type: ignore[attr-defined]
    run.compiled = compiled.compiled  # type: ignore[attr-defined]
    return run


def bangbang_arm(arm: ArmSpec) -> ArmSpec:
    """Seed-001 Section 4.3: payload 2 kg, no gravity, no damping."""
    arm = arm.with_payload(2.0)
    links = tuple(dataclasses.replace(l, damping_ratios=(0.0,)) for l in arm.links)
    joints = tuple(dataclasses.replace(j, friction=0.0) for j in arm.joints)
    return dataclasses.replace(
        arm, gravity=(0.0, 0.0), links=links, joints=joints, configuration=(0.0, 0.0, 0.0)
    )


def bangbang_torque(n_samples: int, sample: float) -> np.ndarray:
    """+50 N m at joint 3 for 0.1 s, then -50 N m for 0.1 s, then zero; one row per sample."""
    t = (np.arange(n_samples) + 0.5) * sample
    U = np.zeros((n_samples, 3))
    U[:, 2] = 50.0 * ((t < 0.1).astype(float) - ((t >= 0.1) & (t < 0.2)).astype(float))
    return U


def bangbang_runs(
    arm: ArmSpec,
    elements: Sequence[int] = (4, 8, 16),
    duration: float = 1.0,
    sample: float = 1e-3,
    amm_substeps: int = 10,
) -> dict:
    """Tip trajectories of AMM-2 and FEM-N in the bang-bang scene, their differences and run
    times."""
    from flexctrl.dynamics.build import build_model

    a = bangbang_arm(arm)
    n = int(round(duration / sample))
    U = bangbang_torque(n, sample)
    t = np.arange(n + 1) * sample
    models = {"amm2": (build_model(a, "amm:2", reference_q=np.zeros(3)), amm_substeps)}
    for N in elements:
        m = build_fem_model(a, N, reference_q=np.zeros(3))
        models[f"fem{N}"] = (m, rk4_step_for(m, sample))
    out: dict = {"t": t.tolist(), "runs": {}}
    tips, w3 = {}, {}
    for name, (m, sub) in models.items():
        run = rk4_sampler(m, sub, sample / sub)
        start = time.perf_counter()
        X = run(np.zeros(m.n_x), U)
        wall = time.perf_counter() - start
        q = X[:, : m.n_q]
        tip = np.array(m.functions["tip"].map(n + 1)(q.T, X[:, m.n_q :].T)[0]).T
        defl = np.array(m.functions["deflection"].map(n + 1)(q.T)[0]).T
        tips[name], w3[name] = tip, defl[:, 2]
        out["runs"][name] = {
            "h_s": sample / sub,
            "omega_max_rad_s": float(m.omega_max),
            "omega_max_h": float(m.omega_max) * sample / sub,
            "wall_s": wall,
            "wall_per_simulated_s": wall / duration,
            "compile_s": run.compile_seconds,
            "compiled": bool(run.compiled),
            "n_q": m.n_q,
            "tip_final_m": tip[-1].tolist(),
            "q_final_rad": q[-1, :3].tolist(),
            "w3_peak_m": float(np.abs(defl[:, 2]).max()),
        }
    ref = f"fem{max(elements)}"
    for name in models:
        if name == ref:
            continue
        d = np.linalg.norm(tips[name] - tips[ref], axis=1)
        dw = w3[name] - w3[ref]
        out["runs"][name][f"tip_vs_{ref}"] = {
            "max_m": float(d.max()),
            "rms_m": float(np.sqrt(np.mean(d**2))),
            "w3_max_m": float(np.abs(dw).max()),
            "w3_rms_m": float(np.sqrt(np.mean(dw**2))),
        }
    out["tip"] = {k: v.tolist() for k, v in tips.items()}
    out["w3"] = {k: v.tolist() for k, v in w3.items()}
    return out


def _median_time(fun: Callable[[], float], repeats: int = 3) -> float:
    return statistics.median(fun() for _ in range(repeats))


def timings(
    arm: ArmSpec,
    elements: Sequence[int] = (4, 8, 16),
    repeats: int = 3,
    newmark_dt: float = 1e-4,
    newmark_span: float = 0.05,
    rk4_span: float = 0.2,
) -> dict:
    """Wall time per simulated second (medians of ``repeats``).

    Beam cases: the paper's settings (4 elements, Newmark dt = 1 ms) over their
    scenes' durations.  Three-link FEM: compiled RK4 at the stability-limited step
    over ``rk4_span`` s of the bang-bang scene, and Newmark (dt = ``newmark_dt``,
    Hessian-of-potential tangents, numpy + CasADi virtual machine) over ``newmark_span`` s.
    """
    from flexctrl.dynamics.fem.newmark import simulate_model_newmark
    from flexctrl.dynamics.fem.sliding_beam import (
        FAST_PULL,
        FAST_PUSH,
        SLOW_PUSH,
        simulate_sliding_beam,
    )

    out: dict = {"beam": {}, "arm": {}}
    for case in (SLOW_PUSH, FAST_PUSH, FAST_PULL):
        dur = max(case.T, 1.0)
        out["beam"][case.name] = {
            "integrator": "newmark+baumgarte",
            "dt": 1e-3,
            "n_elements": 4,
            "wall_per_simulated_s": _median_time(
                lambda case=case, dur=dur: simulate_sliding_beam(case, 4, dt=1e-3).wall_time / dur,
                repeats,
            ),
        }
    a = bangbang_arm(arm)
    sample = 1e-3
    for N in elements:
        m = build_fem_model(a, N, reference_q=np.zeros(3))
        sub = rk4_step_for(m, sample)
        run = rk4_sampler(m, sub, sample / sub)
        n = int(round(rk4_span / sample))
        U = bangbang_torque(n, sample)

        def rk4_once(run=run, m=m, U=U) -> float:
            start = time.perf_counter()
            run(np.zeros(m.n_x), U)
            return (time.perf_counter() - start) / rk4_span

        def newmark_once(m=m) -> float:
            res = simulate_model_newmark(
                m,
                np.zeros(m.n_x),
                newmark_span,
                newmark_dt,
                torque=lambda tt: np.array([0.0, 0.0, 50.0 if tt < 0.1 else -50.0]),
            )
            return res.wall_time / newmark_span

        out["arm"][f"fem{N}"] = {
            "n_q": m.n_q,
            "omega_max_rad_s": float(m.omega_max),
            "rk4": {
                "h_s": sample / sub,
                "compile_s": run.compile_seconds,
                "wall_per_simulated_s": _median_time(rk4_once, repeats),
            },
            "newmark": {
                "dt_s": newmark_dt,
                "tangent": "potential",
                "wall_per_simulated_s": _median_time(newmark_once, repeats),
            },
        }
    return out


def plot_bangbang(runs: dict, path: Path) -> None:
    """Tip position and link-3 deflection of every run against time (PNG)."""
    from matplotlib.figure import Figure

    t = np.asarray(runs["t"])
    fig = Figure(figsize=(8.0, 7.5), layout="constrained")
    ax = fig.subplots(3, 1, sharex=True)
    for name, tip in runs["tip"].items():
        tip = np.asarray(tip)
        ax[0].plot(t, tip[:, 1], label=name, lw=1)
        ax[2].plot(t, np.asarray(runs["w3"][name]) * 1e3, label=name, lw=0.8)
    ref = max((k for k in runs["tip"] if k.startswith("fem")), key=lambda k: int(k[3:]))
    for name, tip in runs["tip"].items():
        if name != ref:
            ax[1].plot(
                t,
                1e3 * np.linalg.norm(np.asarray(tip) - np.asarray(runs["tip"][ref]), axis=1),
                label=name,
                lw=1,
            )
    ax[0].set_ylabel("tip y (m)")
    ax[1].set_ylabel(f"|tip - tip({ref})| (mm)")
    ax[2].set_ylabel("w3 (mm)")
    ax[2].set_xlabel("t (s)")
    ax[0].set_title(
        "bang-bang 50 N m at joint 3 (0.1 s + 0.1 s), payload 2 kg, no gravity, RK4", fontsize=9
    )
    for a in ax:
        a.legend(fontsize=7, loc="best")
        a.grid(True, alpha=0.3)
    fig.savefig(path, dpi=110)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/fem", help="output folder (default out/fem)")
    parser.add_argument("--quick", action="store_true", help="skip the 16-element time-domain runs")
    parser.add_argument("--model", default="subedi3link")
    args = parser.parse_args(argv)
    arm = load_arm(args.model)
    elements = (4, 8) if args.quick else (4, 8, 16)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    report = {"locked_convergence": locked_convergence(arm), "amm_versus_fem": amm_versus_fem(arm)}
    report["bangbang"] = bangbang_runs(arm, elements)
    plot_bangbang(report["bangbang"], out / "bangbang_tip.png")
    report["timings"] = timings(arm, elements)
    (out / "report.json").write_text(json.dumps(report, indent=1))
    np.set_printoptions(precision=4, suppress=True, linewidth=160)
    for row in report["amm_versus_fem"]:
        print(
            row["payload_kg"],
            row["q_deg"],
            "fem16",
            np.array(row["fem16_hz"]),
            "amm2-fem",
            np.array(row["amm2_minus_fem_hz"]),
        )
    for name, run in report["bangbang"]["runs"].items():
        print(name, {k: v for k, v in run.items() if k not in ("tip_final_m",)})
    print(json.dumps(report["timings"], indent=1))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
