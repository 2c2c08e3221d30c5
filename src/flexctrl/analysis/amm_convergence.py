"""Does the assumed-modes model converge onto the finite elements?  Tip errors of ``amm:1..4``
with and without axial shortening against a fine finite-element reference
(``docs/explanation/assumed-modes.md``).

Three cases, each from a scene file of ``studies/scenes`` (RK4 throughout, tip position in the
world frame compared on the output grid):

``bangbang``
    ``bangbang.toml`` (2 kg, no gravity, undamped, +-50 N m at joint 3), first 2 s.
``free_vibration``
    ``free_vibration.toml`` (gravity, joints free, link 3 started bent), first 1 s.  The bent
    start is the *shape* ``w_3(x) = 0.1 phi_1(x) + 0.002 phi_2(x)`` (m) of link 3's clamped-mass
    modes at the start; the finite-element model gets it at its nodes (``w``, ``w'``) with its
    axial dofs relaxed, ``amm:1`` its projection ``q_f31 = 0.1``.
``fast_move``
    ``fast_move_30deg.toml`` (30 deg at joint 1 as a step, 2 kg) closed by ``controllers/lqr.toml``
    designed once on ``amm:2`` (the model's defaults) and measuring joints and link-tip
    deflections (sensors every plant has), first 2 s; only the plant changes.  Every plant is
    damped by the finite elements' rule (``damping_form = "stiffness"``, zeta = 0.005 on each
    link's first mode): their stiffness-proportional damping is all they have.

The reference (``fem:16`` by default, RK4 at its stable step) is cached on disk under the
output folder, keyed by everything that determines it
(:func:`flexctrl.analysis.accuracy.cached_reference`).

Run from a clone (writes ``convergence.json`` and ``convergence.md``)::

    python -m flexctrl.analysis.amm_convergence --out out/amm_convergence
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from flexctrl.analysis.accuracy import Reference, cached_reference
from flexctrl.analysis.simulation_methods import parse_method
from flexctrl.analysis.steppers import make_stepper, run_open_loop
from flexctrl.spec.shipped import data_root

_SCENES = data_root() / "studies" / "scenes"
CASES = {
    "bangbang": ("bangbang.toml", 2.0),
    "free_vibration": ("free_vibration.toml", 1.0),
    "fast_move": ("fast_move_30deg.toml", 2.0),
}
#: Windows (s) over which the RMS tip error is reported, per case.
WINDOWS = {"bangbang": (0.5, 2.0), "free_vibration": (0.5, 1.0), "fast_move": (0.5, 2.0)}
CONTROLLER = "controllers/lqr.toml"
#: Sensors every plant has (strain gauges need assumed modes): joints and link-tip deflections.
CONTROLLER_OVERRIDES = (
    'sensors.outputs=["joints", "deflection"]',
    "sensors.noise={joints_deg = 0.005, deflection = 1e-5}",
)
DESIGN_FIDELITY = "amm:2"
OUTPUT_DT = 1e-3  # s, open loop; the closed loop samples every plant step of 0.5 ms multiples


# : The model variants compared (``docs/explanation/assumed-modes.md`` sections 11 and 14): the
# label, ``axial_shortening``
#: and ``axial_stretch`` of the assumed-modes plant.
VARIANTS = (
    ("off", False, False),
    ("shortening", True, False),
    ("shortening + stretch", True, True),
)


def _scene(case: str, shortening: bool, stretch: bool = False):
    from flexctrl.spec.scene import load_scene

    name, duration = CASES[case]
    scene = load_scene(_SCENES / name)
    if case == "fast_move":
        from flexctrl.spec.fidelity import parse_fidelity

        # the finite elements' damping rule for every plant (docs/explanation/assumed-modes.md
        # section 14): with modal
        # ratios
        # the assumed modes' second modes are 6-13 times less damped than the finite elements'
        plant = dataclasses.replace(
            scene.plant,
            duration=duration,
            axial_shortening=shortening,
            axial_stretch=stretch or None,
            damping_form="stiffness",
        )
        return dataclasses.replace(
            scene, plant=plant, controller_fidelity=parse_fidelity(DESIGN_FIDELITY)
        )
    return dataclasses.replace(
        scene, duration=duration, axial_shortening=shortening, axial_stretch=stretch or None
    )


def _design(scene):
    """The fast move's controller, designed once on ``DESIGN_FIDELITY`` with the assumed-modes
    defaults.

    Every plant then closes the loop with the same controller (the design does not follow the
    plant's ``axial_shortening``/``axial_stretch``), so only the plant changes.
    """
    from flexctrl.scenes.loop_setup import build_loop
    from flexctrl.spec.fidelity import parse_fidelity

    plant = dataclasses.replace(
        scene.plant,
        fidelity=parse_fidelity(DESIGN_FIDELITY),
        axial_shortening=None,
        axial_stretch=None,
        damping_form=None,
    )
    setup = build_loop(
        dataclasses.replace(scene, plant=plant),
        str(_SCENES.parents[1] / CONTROLLER),
        CONTROLLER_OVERRIDES,
    )
    return setup.controller


def _bent_start(scene, model, arm) -> np.ndarray:
    """The free-vibration start as a shape of link 3 (module docstring), in ``model``'s
    coordinates."""
    from flexctrl.modal.arm_modes import link_modes
    from flexctrl.scenes.arm_setup import initial_state

    x0 = initial_state(dataclasses.replace(scene, qf0={}), model, arm)
    amplitudes = {int(k[3:]) - 1: v for k, v in scene.qf0.items()}  # qf3j -> mode j-1 of link 3
    link = 2
    if not amplitudes:
        return x0
    if str(model.fidelity).startswith("amm"):
        for j, value in amplitudes.items():
            name = f"qf{link + 1}{j + 1}"
            if name in model.coordinate_names:
                x0[model.coordinate_names.index(name)] = value
        return x0
    from flexctrl.dynamics.fem.fem_arm import relax_axial

    modes = link_modes(arm, x0[: arm.n_links], link, max(amplitudes) + 1)
    N = model.info["n_elements"]
    nodes = np.arange(1, N + 1) * arm.links[link].length / N
    c = np.zeros(modes.n_modes)
    for j, value in amplitudes.items():
        c[j] = value
    w, th = c @ modes.shape(nodes), c @ modes.shape(nodes, 1)
    names = list(model.coordinate_names)
    for k in range(N):
        x0[names.index(f"w{link + 1}_{k + 1}")] = w[k]
        x0[names.index(f"th{link + 1}_{k + 1}")] = th[k]
    x0[: model.n_q] = relax_axial(model, x0[: model.n_q])
    return x0


def _simulate_closed_loop(case: str, scene, method, fidelity: str) -> dict[str, Any]:
    """The closed-loop case: the LQR loop with the plant at ``fidelity``."""
    from flexctrl.dynamics.build import build_model
    from flexctrl.dynamics.fem.locked_spectrum import rk4_step_for
    from flexctrl.scenes.arm_setup import scene_arm
    from flexctrl.scenes.loop_setup import closed_loop_tip_path

    sample = 5e-4
    start = time.perf_counter()
    if method.step is None:
        arm = scene_arm(scene.plant)
        h = sample / rk4_step_for(build_model(arm, fidelity, reference_q=scene.plant.q0), sample)
    else:
        h = method.step
    stride = max(1, int(round(sample / h)))
    controller = _design(scene)
    out = closed_loop_tip_path(
        dataclasses.replace(scene, controller_fidelity=None),
        fidelity,
        h,
        controller=controller,
        stride=stride,
    )
    if out["diverged_at"] is not None:
        raise RuntimeError(f"{case} {fidelity} diverged at {out['diverged_at']} s")
    return {
        "time": out["time"],
        "tip": out["tip"][:, :2],
        "wall_s": out["wall_time_s"],
        "setup_s": time.perf_counter() - start - out["wall_time_s"],
        "step_s": h,
    }


def simulate(
    case: str,
    fidelity: str,
    shortening: bool,
    step: str = "stable",
    hub_inertia: float | None = None,
    static_correction: bool = False,
    stretch: bool = False,
) -> dict[str, Any]:
    """One run: ``time`` (s), ``tip`` (m, (T, 2)), ``wall_s`` (integration), ``setup_s`` (build +
    compile).

    ``hub_inertia`` (kg m^2, open-loop cases only): every hub's rotor inertia raised to at least
    this (a diagnosis of how the light hub 3 limits the convergence;
    ``docs/explanation/assumed-modes.md`` section 11).
    """
    from flexctrl.dynamics.build import build_model
    from flexctrl.scenes.arm_setup import scene_arm

    scene = _scene(case, shortening, stretch and fidelity.startswith("amm:"))
    method = parse_method(f"{fidelity}/rk4@{step}")
    if case == "fast_move" and hub_inertia is not None:
        raise ValueError("hub_inertia applies to the open-loop cases only")
    if case == "fast_move":
        return _simulate_closed_loop(case, scene, method, fidelity)
    arm = scene_arm(scene)
    if hub_inertia is not None:
        arm = dataclasses.replace(
            arm,
            joints=tuple(
                dataclasses.replace(j, hub_inertia=max(j.hub_inertia, hub_inertia))
                for j in arm.joints
            ),
        )
    start = time.perf_counter()
    if static_correction and fidelity.startswith("amm:"):
        from flexctrl.dynamics.amm import build_amm

        model = build_amm(
            arm,
            int(fidelity[4:]),
            reference_q=scene.q0,
            static_correction=True,
            axial_stretch=stretch,
        )
    else:
        model = build_model(arm, fidelity, reference_q=scene.q0)
    stepper = make_stepper(model, method, OUTPUT_DT)
    setup = time.perf_counter() - start
    x0 = _bent_start(scene, model, arm)
    n = int(round(scene.duration / OUTPUT_DT))
    run = run_open_loop(stepper, x0, scene.input.samples(n, OUTPUT_DT, model.n_u))
    if not np.all(np.isfinite(run.tip)):
        raise RuntimeError(f"{case} {fidelity} produced a non-finite tip")
    return {
        "time": run.time,
        "tip": run.tip,
        "wall_s": run.wall_s,
        "setup_s": setup,
        "step_s": stepper.step_s,
        "build_s": float(model.info["build_time_s"]),
        "f_instructions": int(model.functions["f"].n_instructions()),
        "us_per_step": 1e6 * run.wall_s / (n * stepper.substeps)
        if hasattr(stepper, "substeps")
        else math.nan,
    }


def reference(
    case: str,
    fidelity: str = "fem:16",
    directory: Path | str = "out/amm_convergence",
    hub_inertia: float | None = None,
) -> Reference:
    """The cached reference tip path of ``case`` (finite elements with axial shortening, RK4 at the
    stable step)."""
    name, duration = CASES[case]
    digest = {
        k: (_SCENES / f).read_text()
        for k, f in (("scene", name), ("model", "../../models/subedi3link.toml"))
    }
    key = {
        "case": case,
        "fidelity": fidelity,
        "duration": duration,
        "files": digest,
        "controller": (_SCENES.parents[1] / CONTROLLER).read_text()
        if case == "fast_move"
        else None,
    }
    if hub_inertia is not None:
        key["hub_inertia"] = hub_inertia

    def build() -> Reference:
        run = simulate(case, fidelity, True, hub_inertia=hub_inertia)
        return Reference(run["time"], run["tip"], f"{fidelity}/rk4@stable", {}, run["wall_s"])

    ref, _path, _hit = cached_reference(key, build, Path(directory))
    return ref


def window_errors(
    ref: Reference, run: dict[str, Any], windows: Sequence[float]
) -> dict[str, float]:
    """RMS tip distance (m) from the reference over ``[0, T]`` for each ``T`` of ``windows``, and
    the max over all."""
    tip = np.column_stack([np.interp(ref.time, run["time"], run["tip"][:, k]) for k in range(2)])
    d = np.linalg.norm(tip - ref.tip, axis=1)
    out = {f"rms_{T:g}s": float(np.sqrt(np.mean(d[ref.time <= T + 1e-9] ** 2))) for T in windows}
    out["max"] = float(d.max())
    return out


def convergence(
    case: str,
    modes: Sequence[int] = (1, 2, 3, 4),
    reference_fidelity: str = "fem:16",
    directory: Path | str = "out/amm_convergence",
    steps: dict[int, str] | None = None,
    hub_inertia: float | None = None,
    static_correction: bool = False,
) -> dict[str, Any]:
    """Tip errors of ``amm:N`` for N in ``modes``, with and without axial shortening, against the
    reference.

    ``steps`` maps N to the RK4 step (default ``0.1ms``, ``0.05ms`` for N >= 4).
    """
    ref = reference(case, reference_fidelity, directory, hub_inertia)
    steps = steps or {}
    rows: list[dict[str, Any]] = []
    for label, shortening, stretch in VARIANTS:
        for N in modes:
            step = steps.get(N, "0.05ms" if N >= 4 else "0.1ms")
            run = simulate(
                case, f"amm:{N}", shortening, step, hub_inertia, static_correction, stretch
            )
            rows.append(
                {
                    "fidelity": f"amm:{N}",
                    "variant": label,
                    "axial_shortening": shortening,
                    "axial_stretch": stretch,
                    "step": step,
                    **window_errors(ref, run, WINDOWS[case]),
                    "wall_per_sim_s": run["wall_s"] / ref.time[-1],
                    **{
                        k: run[k]
                        for k in ("setup_s", "build_s", "f_instructions", "us_per_step")
                        if k in run
                    },
                }
            )
    return {
        "case": case,
        "reference": ref.method,
        "windows_s": list(WINDOWS[case]),
        "rows": rows,
        "hub_inertia": hub_inertia,
    }


def markdown(result: dict[str, Any]) -> str:
    """The table of ``docs/explanation/assumed-modes.md`` for one :func:`convergence` result
    (mm)."""
    windows = result["windows_s"]
    variants = list(
        dict.fromkeys(
            r.get("variant", "on" if r["axial_shortening"] else "off") for r in result["rows"]
        )
    )
    by_variant = {
        v: [
            r
            for r in result["rows"]
            if r.get("variant", "on" if r["axial_shortening"] else "off") == v
        ]
        for v in variants
    }
    first = by_variant[variants[0]]
    head = "| model, window | " + " | ".join(r["fidelity"] for r in first) + " |"
    hub = (
        ""
        if result.get("hub_inertia") is None
        else f", hub inertia >= {result['hub_inertia']:g} kg m^2"
    )
    rule = "|" + "---|" * (1 + len(first))
    lines = [
        f"{result['case']} against {result['reference']}{hub}: RMS tip error (mm)",
        "",
        head,
        rule,
    ]
    for T in windows:
        for v in variants:
            vals = [r[f"rms_{T:g}s"] * 1e3 for r in by_variant[v]]
            lines.append(f"| {v}, 0-{T:g} s | " + " | ".join(f"{x:.3f}" for x in vals) + " |")
    if "us_per_step" in result["rows"][0]:
        lines += [
            "",
            "cost: compiled RK4 step (us) / model build (s) / instructions in f",
            "",
            head.replace("model, window", "model"),
            rule,
        ]
        for v in variants:
            cells = [
                f"{r['us_per_step']:.2f} / {r['build_s']:.2f} / {r['f_instructions'] / 1e3:.1f}k"
                for r in by_variant[v]
            ]
            lines.append(f"| {v} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m flexctrl.analysis.amm_convergence", description=__doc__.split("\n")[0]
    )
    parser.add_argument(
        "--out", default="out/amm_convergence", help="output and reference-cache folder"
    )
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    parser.add_argument("--modes", nargs="+", type=int, default=[1, 2, 3, 4])
    parser.add_argument(
        "--reference", default="fem:16", help="finite-element reference fidelity (default fem:16)"
    )
    parser.add_argument(
        "--reference-only", action="store_true", help="compute (or load) the references and stop"
    )
    parser.add_argument(
        "--hub-inertia",
        type=float,
        default=None,
        help="raise every hub's rotor inertia to at least this (kg m^2; open-loop cases; a "
        "diagnosis)",
    )
    parser.add_argument(
        "--static-correction",
        action="store_true",
        help="assumed modes with the tip-moment correction shapes "
        "(docs/explanation/assumed-modes.md section 13)",
    )
    parser.add_argument(
        "--tag", default="", help="suffix of the output files (convergence<TAG>.json/.md)"
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = []
    for case in args.cases:
        if args.reference_only:
            ref = reference(case, args.reference, out, args.hub_inertia)
            print(
                f"{case}: reference {ref.method}, {ref.time.size} samples, {ref.wall_s:.1f} s",
                flush=True,
            )
            continue
        result = convergence(
            case,
            args.modes,
            args.reference,
            out,
            hub_inertia=args.hub_inertia,
            static_correction=args.static_correction,
        )
        results.append(result)
        print(markdown(result), "\n", flush=True)
    if results:
        (out / f"convergence{args.tag}.json").write_text(json.dumps(results, indent=1))
        (out / f"convergence{args.tag}.md").write_text(
            "\n\n".join(markdown(r) for r in results) + "\n"
        )
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
