"""Redraw the figures of README.md and docs/ into docs/figures/ (``make figures``).

What it runs (each study in a reduced form, its results kept in ``out/figures/<name>``
and resumed, so a second ``make figures`` only redraws; ``--fresh`` reruns them):

``comparison.png``
    PD, LQR and MPC (``controllers/``) on the 30-degree joint-1 move at 2 kg (amm:2,
    horizontal plane, 1.5 s quintic, 8 s), drawn by ``fc.compare``: the README's example.
``stability_map.png``
    ``studies/controller_stability.toml`` with PD, LQR, the payload-aware LQR and the robust
    controller only (3 payloads x 12 poses x 4 controllers = 144 runs);
    the study report's map of ``stable``.
``pareto.png``
    ``studies/speed_vs_accuracy.toml`` on the bang-bang scene at 2 kg, the straight arm,
    nine methods (about a minute, one worker: timings are the point); its Pareto chart.
``pareto_shortening.png``
    The same case and methods with ``studies/speed_vs_accuracy_shortening.toml`` (the
    assumed-modes models' axial shortening on) beside the shipped study's, drawn by
    ``flexctrl.analysis.pareto_compare`` (the shipped side is the ``pareto`` study, resumed).
``mode_shapes.png``, ``frequency_maps.png``
    The modes of ``models/subedi3link.toml`` (Subedi et al. 2021, Figs 2, 6 and 7): the
    mode shapes of every link at 0 and 2 kg, the first two link-1 frequencies over
    (q2, q3) and the link-2 ones over q3 at 2 kg (15-degree grid; seconds).

Run from the repository root: ``python tools/make_figures.py [--only NAME ...] [--workers N]``.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ROOT / "docs" / "figures"
OUT = ROOT / "out" / "figures"
DPI = 80  # small files: the docs show them at page width
DAMPED = [f"links[{i}].damping_ratio=0.005" for i in (1, 2, 3)]


def comparison(args) -> Path:
    import flexctrl as fc

    model = fc.load_model(
        "subedi3link",
        payload=2.0,
        fidelity="amm:2",
        gravity=[0.0, 0.0],
        overrides=DAMPED,
    )
    op = fc.equilibrium(model, np.radians([30.0, 0.0, 0.0]))
    move = fc.Move(start=np.radians([0, 0, 0]), target=np.radians([30, 0, 0]), time=1.5)
    judge = fc.MetricSettings(settle_allowance=1.0)
    results = {}
    for name in ("pd", "lqr", "mpc"):
        controller = fc.design(model, op, fc.load_controller(name))
        results[name.upper()] = fc.closed_loop(model, controller, move, duration=8.0, metrics=judge)
    fig = fc.compare(
        results,
        title="30 degree move of joint 1 at 2 kg (amm:2, 1.5 s quintic), controllers/*.toml",
    )
    return _save(fig, "comparison.png")


def _study(name: str, study: str, overrides: list[str], args, workers: int | None = None) -> Path:
    import flexctrl as fc

    out = OUT / name
    if args.fresh and out.exists():
        shutil.rmtree(out)
    spec = fc.load_study(study, overrides)
    try:
        fc.run_study(
            spec,
            out,
            resume=out.exists(),
            workers=args.workers if workers is None else workers,
            progress="lines",
        )
    except fc.SpecError:  # the folder holds another version of the study: run it afresh
        shutil.rmtree(out)
        fc.run_study(
            spec, out, workers=args.workers if workers is None else workers, progress="lines"
        )
    return out


def stability_map(args) -> Path:
    out = _study(
        "controller_stability",
        "studies/controller_stability.toml",
        [
            'grid.controller=["../controllers/pd.toml", "../controllers/lqr.toml", '
            '"../controllers/lqr_payload.toml", "../controllers/robust.toml"]'
        ],
        args,
    )
    return _copy(out / "figures" / "map_stable.png", "stability_map.png")


PARETO_METHODS = [
    "rigid/rk4@1ms",
    "amm:1/rk4@1ms",
    "amm:2/rk4@1ms",
    "amm:2/rk4@0.25ms",
    "amm:3/rk4@0.25ms",
    "amm:2/newmark@1ms",
    "amm:2/cvodes@1e-6",
    "fem:2/rk4@stable",
    "fem:4/rk4@stable",
]
PARETO_CASE = [
    'grid.scene=["scenes/bangbang.toml"]',
    "grid.payload=[2.0]",
    "grid.configuration=[[0, 0, 0]]",
    'grid."scene.method"=[' + ", ".join(f'"{m}"' for m in PARETO_METHODS) + "]",
]


def pareto(args) -> Path:
    out = _study(
        "speed_vs_accuracy", "studies/speed_vs_accuracy.toml", PARETO_CASE, args, workers=1
    )
    return _copy(out / "figures" / "pareto.png", "pareto.png")


def pareto_shortening(args) -> Path:
    from flexctrl.analysis.pareto_compare import compare, plot, read_pareto

    off = _study(
        "speed_vs_accuracy", "studies/speed_vs_accuracy.toml", PARETO_CASE, args, workers=1
    )
    on = _study(
        "speed_vs_accuracy_shortening",
        "studies/speed_vs_accuracy_shortening.toml",
        PARETO_CASE,
        args,
        workers=1,
    )
    return plot(
        compare(read_pareto(off), read_pareto(on)),
        FIGURES / "pareto_shortening.png",
        ("axial shortening off", "on"),
        title="bang-bang at 2 kg, straight arm: assumed-modes axial shortening off (hollow) and "
        "on (filled)\n"
        "(the finite elements have it in both; arrows: where a method moved)",
        dpi=DPI,
    )


def modes(args) -> list[Path]:
    from matplotlib.figure import Figure

    from flexctrl.modal.arm_modes import arm_modes
    from flexctrl.modal.mode_plots import frequency_maps
    from flexctrl.spec.arm import load_arm

    arm = load_arm("subedi3link")
    fig = Figure(figsize=(10.5, 3.6), layout="constrained")
    axes = fig.subplots(1, arm.n_links)
    for payload, style in ((0.0, "--"), (2.0, "-")):
        for link, link_modes in enumerate(
            arm_modes(arm.with_payload(payload), np.zeros(arm.n_links), 2)
        ):
            x = np.linspace(0.0, arm.links[link].length, 151)
            for j, shape in enumerate(link_modes.shape(x)):
                axes[link].plot(
                    x,
                    shape,
                    ls=style,
                    color=f"C{j}",
                    label=f"mode {j + 1}, {payload:g} kg: {link_modes.frequency_hz[j]:.2f} Hz",
                )
    for link, ax in enumerate(axes):
        ax.set_title(f"link {link + 1}", fontsize=9)
        ax.set_xlabel("position along the link x (m)")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=6.5)
    axes[0].set_ylabel("mode shape phi (-)")
    fig.suptitle(
        "clamped-mass mode shapes of the straight arm (q = 0 deg), normalised to the link mass; "
        "dashed: no payload, solid: 2 kg",
        fontsize=9,
    )
    paths = [_save(fig, "mode_shapes.png")]

    maps = frequency_maps(arm.with_payload(2.0), 15.0, "exact")
    grid = maps["grid_deg"]
    fig = Figure(figsize=(10.5, 3.2), layout="constrained")
    axes = fig.subplots(1, 3)
    for mode in range(2):
        mesh = axes[mode].pcolormesh(grid, grid, maps["link1"][..., mode].T, shading="auto")
        fig.colorbar(mesh, ax=axes[mode], label=f"f1{mode + 1} (Hz)")
        axes[mode].set_title(f"link 1, mode {mode + 1}", fontsize=9)
        axes[mode].set_xlabel("q2 (deg)")
        axes[mode].set_ylabel("q3 (deg)")
    for mode in range(2):
        axes[2].plot(grid, maps["link2"][:, mode], label=f"f2{mode + 1}")
    axes[2].set_title("link 2", fontsize=9)
    axes[2].set_xlabel("q3 (deg)")
    axes[2].set_ylabel("frequency (Hz)")
    axes[2].legend(fontsize=7)
    axes[2].grid(True, alpha=0.3)
    fig.suptitle(
        "clamped-mass frequencies over the configuration, 2 kg payload (exact boundary inertia)",
        fontsize=9,
    )
    paths.append(_save(fig, "frequency_maps.png"))
    return paths


def _save(fig, name: str) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    path = FIGURES / name
    fig.savefig(path, dpi=DPI)
    return path


def _copy(source: Path, name: str) -> Path:
    """A study report's figure, as the report drew it."""
    return Path(shutil.copy(source, FIGURES / name))


FIGURE_MAKERS = {
    "comparison": comparison,
    "stability_map": stability_map,
    "pareto": pareto,
    "pareto_shortening": pareto_shortening,
    "modes": modes,
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--only", nargs="+", choices=sorted(FIGURE_MAKERS), help="redraw only these"
    )
    parser.add_argument("--workers", type=int, default=2, help="study workers (default 2)")
    parser.add_argument(
        "--fresh", action="store_true", help="rerun the studies instead of resuming them"
    )
    args = parser.parse_args(argv)
    FIGURES.mkdir(parents=True, exist_ok=True)
    for name in args.only or FIGURE_MAKERS:
        start = time.perf_counter()
        made = FIGURE_MAKERS[name](args)
        for path in made if isinstance(made, list) else [made]:
            print(
                f"{path.relative_to(ROOT)} ({path.stat().st_size / 1024:.0f} KiB, "
                f"{time.perf_counter() - start:.0f} s)"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
