"""Pan, Scott & Ulsoy (1990), Figs 1-5: the floating frames, the axial shortening and the joints.

The five figures are schematics; each is set beside a run of the toolkit's model of it:

* Fig 1 (two-link R-P robot, frames following the nominal motion): ``models/rp_arm.toml``
  extending while it turns, partial coupling (Eq 42) and full coupling fed the same motion (Eq 43);
* Fig 2 (axial shortening, Eqs 11-18): the frequency of a spinning cantilever against Southwell's
  coefficient;
* Fig 3 (revolute joint, Eqs 19-21): the three-link finite-element arm, joints eliminated by
  clamped frames, against the assumed-modes arm's locked frequencies;
* Fig 4 (prismatic joint in a rigid link, Eqs 22-25): ``models/rp_arm_clamped.toml``;
* Fig 5 (telescoping joint, Eqs 26-28): ``models/telescoping.toml``, partial and full coupling.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from flexctrl.dynamics.fem.full_coupling import RPForces
from flexctrl.dynamics.fem.moving_frame import FrameLink, RPMotion
from flexctrl.dynamics.fem.rp_arm import RPArmModel, simulate_rp_arm
from flexctrl.dynamics.fem.rp_arm_full import simulate_rp_arm_full
from flexctrl.dynamics.fem.sliding_beam import FAST_PUSH, simulate_sliding_beam
from flexctrl.dynamics.fem.telescoping import (
    TelescopingModel,
    simulate_telescoping,
    static_tip_deflection,
)
from flexctrl.dynamics.fem.telescoping_full import simulate_telescoping_full
from flexctrl.reproduce.items import Item, Section
from flexctrl.spec.fem_models import RPArmSpec, load_rp_arm, load_telescoping
from flexctrl.spec.shipped import data_root

ROOT = data_root()
# : The rest-to-rest move of ``studies/scenes/rp_extend_rotate.toml``: W 0.3 -> 0.7 m, 0 -> 60 deg
# in 1 s.
EXTEND = RPMotion(C1=0.3, C2=-0.4, T=1.0, dtheta=math.radians(60.0))
# : Southwell's coefficient of the first mode of a uniform cantilever (omega^2 = omega_0^2 + S
# Omega^2
#: out of the plane of rotation; in the plane the frame's -Omega^2 softening makes it S - 1).
SOUTHWELL = 1.1933


def _gap(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(np.asarray(a) - np.asarray(b)).max())


def fig1(out_dir: Path, reduced: bool) -> Section:
    spec = load_rp_arm(ROOT / "models" / "rp_arm.toml")
    n = 4 if reduced else 8
    duration = 1.5
    part = simulate_rp_arm(spec, EXTEND, n, dt=1e-3, duration=duration)
    full = simulate_rp_arm_full(spec, EXTEND, n, dt=1e-3, duration=duration)
    peak = float(np.abs(part.tip_y).max())
    beam = RPArmSpec("beam", 1.0, 1.0, 1.0, 0.75, 1.0)
    fixed = simulate_rp_arm(
        beam,
        RPMotion(C1=FAST_PUSH.C1, C2=FAST_PUSH.C2, T=FAST_PUSH.T),
        4,
        dt=1e-3,
        duration=1.0,
        driven_end="H",
        initial="static_load",
    )
    reference = simulate_sliding_beam(FAST_PUSH, 4, dt=1e-3)
    items = [
        Item(
            "Fig 1, floating frame of the sliding link",
            "frames follow the nominal (rigid) motion; small "
            "displacements measured from them (Eqs 1-7)",
            "housing held fixed: the R-P arm is the beam of Figs 6-9, tip difference "
            f"{_gap(fixed.tip_y, reference.tip_y):.1e} m",
            _gap(fixed.tip_y, reference.tip_y) < 1e-10,
            "two independent codes of the same equations "
            "(rp_arm.py with a turning frame, sliding_beam.py with a translating one)",
        ),
        Item(
            "Fig 1, partial against full coupling",
            "prescribed motion (Eq 42) assumes the elastic motion "
            "hardly disturbs the rigid one; full coupling (Eq 43) solves both",
            f"full coupling fed the same motion: tip {_gap(full.tip_y, part.tip_y):.1e} m from "
            "partial "
            f"(peak {1e3 * peak:.2f} mm); torque {full.torque.min():.1f} .. "
            f"{full.torque.max():.1f} N m, "
            f"force {full.force.min():.1f} .. {full.force.max():.1f} N needed",
            _gap(full.tip_y, part.tip_y) < 1e-3 * peak,
            "the Lagrangian of the full model keeps the shortening in T; with the motion imposed "
            "its nodal rows "
            "are Eq 42 with Pan's K_g (bound 0.1 % of the peak; the gap is the O(dt^2) joint "
            "tracking)",
        ),
    ]
    _draw_arm(part, spec, out_dir / "figures" / "fig1_rp_arm.png")
    return Section(
        "Fig 1: two-link robot with a revolute and a prismatic joint",
        "`models/rp_arm.toml` (chosen laboratory-scale parameters: the paper's Part II data are "
        "not in "
        "the text): the link extends from W = 0.3 to 0.7 m while the housing turns 60 deg in 1 s, "
        f"{n} elements, Newmark + Baumgarte, dt = 1 ms.",
        items,
        ["figures/fig1_rp_arm.png"],
    )


def _draw_arm(res, spec, path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.0, 4.6), layout="constrained")
    ax, bx = fig.subplots(1, 2)
    scale = 50.0
    model = res.model
    x = np.linspace(0.0, spec.length, 41)
    from flexctrl.dynamics.fem.moving_frame import point_rows

    rows = point_rows(x, model.n, spec.length, 0)[0]
    for k, t in enumerate((0.0, 0.25, 0.5, 0.75, 1.0, 1.5)):
        i = int(np.argmin(np.abs(res.t - t)))
        th, W, q = res.theta[i], res.W[i], res.q[i]
        rE = spec.support_outer - spec.length + W
        w = scale * (rows @ q)
        X, Y = (rE + x) * np.cos(th) - w * np.sin(th), (rE + x) * np.sin(th) + w * np.cos(th)
        ax.plot(X, Y, color=f"C{k}", label=f"t = {t:g} s")
        r = np.array([spec.support_inner, spec.support_outer])
        ax.plot(r * np.cos(th), r * np.sin(th), "k^", ms=5)
    ax.plot(0, 0, "ko")
    ax.set_aspect("equal")
    ax.set_xlabel("X (m)")
    ax.set_ylabel("Y (m)")
    ax.set_title(f"R-P arm, deflection drawn x{scale:g}; supports ^", fontsize=10)
    ax.legend(fontsize=7)
    ax.grid(True, alpha=0.3)
    bx.plot(res.t, 1e3 * res.tip_y, label="tip H, transverse")
    bx.set_xlabel("t (s)")
    bx.set_ylabel("tip H transverse displacement (mm)")
    bx.grid(True, alpha=0.3)
    cx = bx.twinx()
    cx.plot(res.t, 100 * res.W, "C1--", label="W (cm)")
    cx.plot(res.t, np.degrees(res.theta), "C2:", label="theta (deg)")
    cx.set_ylabel("W (cm), theta (deg)")
    lines = bx.get_lines() + cx.get_lines()
    bx.legend(lines, [ln.get_label() for ln in lines], fontsize=8, loc="upper left")
    fig.savefig(path, dpi=100)


def fig2() -> Section:
    link = FrameLink(8, 1.0, 1.0, 1.0)
    K0, M = link.K[2:, 2:], link.M[2:, 2:]
    w0 = float(np.sqrt(np.linalg.eigvals(np.linalg.solve(M, K0)).real.min()))
    Omega = 0.1 * w0
    coefficient = {}
    for sh in (True, False):
        Kt, _ = link.terms(
            {
                "rE": 0.0,
                "rEd": 0.0,
                "rEdd": 0.0,
                "thd": Omega,
                "thdd": 0.0,
                "g_ax": 0.0,
                "g_perp": 0.0,
            },
            "E",
            sh,
        )
        w2 = float(np.linalg.eigvals(np.linalg.solve(M, Kt[2:, 2:])).real.min())
        coefficient[sh] = (w2 - w0**2) / Omega**2
    items = [
        Item(
            "Fig 2, axial shortening of a bent link (Eqs 14-18)",
            f"the work of the axial force through "
            "dL = 1/2 w'^2 dx stiffens a link in tension; for a spinning cantilever Southwell's "
            "coefficient "
            f"gives (omega^2 - omega_0^2) / Omega^2 = {SOUTHWELL} - 1 = {SOUTHWELL - 1:.4f} in "
            "the plane",
            f"{coefficient[True]:.4f} (8 elements, Omega = 0.1 omega_0); without the term "
            f"{coefficient[False]:.4f}",
            abs(coefficient[True] - (SOUTHWELL - 1)) < 0.01,
            "the frame's centrifugal softening alone gives -1; K_g of the centrifugal tension "
            "(Eq 17, reaction "
            "at the clamp) restores Southwell's value; bound 0.01",
        )
    ]
    return Section(
        "Fig 2: axial shortening of a beam under plane transverse deflection",
        "A uniform cantilever (EI = 1 N m^2, rho = 1 kg/m, L = 1 m) clamped in a frame spinning at "
        "Omega about its root, the terms of `FrameLink.terms` (the prescribed-motion model's).",
        items,
    )


def fig3() -> Section:
    from flexctrl.dynamics.fem.locked_spectrum import locked_amm_hz, locked_fem_hz
    from flexctrl.spec.arm import load_arm

    arm = load_arm(ROOT / "models" / "subedi3link.toml").with_payload(2.0)
    q = (0.0, 45.0, -90.0)
    fem, amm = locked_fem_hz(arm, 4, q, 3), locked_amm_hz(arm, 4, q, 3)
    rel = float(np.abs(fem / amm - 1.0).max())
    items = [
        Item(
            "Fig 3, revolute-joint compatibility (Eqs 19-21)",
            "displacement and slope continuous at the "
            "joint, as constraints with multipliers between frames on the nominal motion",
            "eliminated: each link clamped in a frame at the deformed tip of the previous one; "
            "locked "
            f"frequencies of the three-link arm (2 kg, q = (0, 45, -90) deg), 4 elements per link: "
            f"{', '.join(f'{f:.4f}' for f in fem)} Hz against the assumed-modes arm's "
            f"{', '.join(f'{f:.4f}' for f in amm)} Hz",
            rel < 1e-3,
            f"largest relative difference {rel:.1e} (bound 1e-3: the assumed-modes links are "
            "axially rigid, "
            "docs/explanation/finite-elements.md section 2); in the plane the constraints are "
            "linear in the nodal "
            "values, so "
            "eliminating them is exact and leaves an ODE without drift",
        )
    ]
    return Section(
        "Fig 3: revolute joint",
        "The three-link arm of `models/subedi3link.toml` "
        "(`build_fem_model`), the two independent discretisations side by side.",
        items,
    )


def fig4(out_dir: Path, reduced: bool) -> Section:
    spec = load_rp_arm(ROOT / "models" / "rp_arm_clamped.toml")
    P, items = 2.0, []
    for W in (0.25, 0.5):
        model = RPArmModel(spec, RPMotion(C1=W, C2=0.0, T=1.0), 8)
        q, _ = model.static(P)
        a, c = spec.length - W, W
        closed = P * c**2 * a / (4 * spec.EI) + P * c**3 / (3 * spec.EI)
        slope = model._rows(0.0)[1][2] @ q
        items.append(
            Item(
                f"Fig 4, static tip deflection, W = {W:g} m",
                "link clamped at E (Eqs 22-23), held at "
                "the mouth D' (Eq 24): a cantilever of the free length W beyond D' on a propped "
                "span",
                f"{1e3 * q[model.tip]:.4f} mm; overhang on the tangent at D' "
                f"{1e3 * (q[model.tip] - slope * c):.4f} mm",
                abs(q[model.tip] / closed - 1) < 1e-9
                and abs((q[model.tip] - slope * c) / (P * c**3 / (3 * spec.EI)) - 1) < 1e-9,
                f"closed form P c^2 a / (4 EI) + P c^3 / (3 EI) = {1e3 * closed:.4f} mm, "
                "cantilever "
                f"P c^3 / (3 EI) = {1e3 * P * c**3 / (3 * spec.EI):.4f} mm (P = {P:g} N, mouth "
                "on a node)",
            )
        )
    n = 4 if reduced else 8
    clamped = simulate_rp_arm(spec, EXTEND, n, dt=1e-3, duration=1.5)
    supports = simulate_rp_arm(
        load_rp_arm(ROOT / "models" / "rp_arm.toml"), EXTEND, n, dt=1e-3, duration=1.5
    )
    full = simulate_rp_arm_full(spec, EXTEND, n, dt=1e-3, duration=1.5)
    peak = float(np.abs(clamped.tip_y).max())
    items += [
        Item(
            "Fig 4, prescribed motion (Eq 42)",
            "the clamp and the moving contact point D' as constraints",
            f"peak tip {1e3 * peak:.2f} mm (two supports instead: "
            f"{1e3 * np.abs(supports.tip_y).max():.2f} mm); "
            f"max |Phi| {clamped.phi_violation.max():.1e} m",
            clamped.phi_violation.max() < 1e-6,
            "clamp rows fixed on the link, mouth row sliding; bound 1e-6 m",
        ),
        Item(
            "Fig 4, prescribed torque/force (Eq 43) against prescribed motion",
            "full coupling retains both directions of the rigid-elastic coupling",
            f"fed the same motion: tip {_gap(full.tip_y, clamped.tip_y):.1e} m from the partial "
            "model",
            _gap(full.tip_y, clamped.tip_y) < 1e-3 * peak,
            "bound 0.1 % of the peak; rigid limit against solve_ivp: "
            "tests/dynamics/fem/test_prismatic_clamped.py",
        ),
    ]
    _time_plot(
        out_dir / "figures" / "fig4_clamped_joint.png",
        "Extend 0.4 m and turn 60 deg in 1 s",
        "tip H transverse displacement (mm)",
        [
            (clamped, clamped.tip_y, "-", "Fig 4 joint: clamped at E, bearing at the mouth"),
            (full, full.tip_y, "--", "same, full coupling fed the motion"),
            (supports, supports.tip_y, ":", "two bilateral supports (models/rp_arm.toml)"),
        ],
    )
    return Section(
        "Fig 4: prismatic joint, link i moving in and out of a rigid link i-1",
        '`models/rp_arm_clamped.toml` (`[housing] joint = "clamped"`): the link of '
        "`models/rp_arm.toml` clamped at its inner end E in the carriage and held by one bilateral "
        f"bearing at the housing mouth; the move of Fig 1, {n} elements.",
        items,
        ["figures/fig4_clamped_joint.png"],
    )


def fig5(out_dir: Path, reduced: bool) -> Section:
    spec = load_telescoping(ROOT / "models" / "telescoping.toml")
    motion = RPMotion(C1=0.1, C2=-0.4, T=0.6, dtheta=math.radians(60.0))
    n = 4 if reduced else 8
    part = simulate_telescoping(spec, motion, n, n, dt=1e-3, duration=1.0)
    full = simulate_telescoping_full(spec, motion, n, n, dt=1e-3, duration=1.0)
    forces = RPForces.from_samples(full.t, full.torque, full.force, theta0=0.0, W0=motion.C1)
    replay = simulate_telescoping_full(spec, forces, n, n, dt=1e-3, duration=1.0)
    peak = float(np.abs(part.tip_y).max())
    s = spec.outer.length - spec.inner.length + 0.3
    static = TelescopingModel(spec, dataclasses.replace(motion, C1=0.3, C2=0.0), 8, 8).static(1.0)[
        0
    ]
    closed = static_tip_deflection(spec, s, 1.0)
    tip_dof = TelescopingModel(spec, motion, 8, 8).tip
    items = [
        Item(
            "Fig 5, contacts (Eqs 26-28)",
            "equal displacements (and slopes) of the two flexible links at the "
            "joint point D', which moves along both",
            f"static tip under 1 N at W = 0.3 m: "
            f"{1e3 * static[tip_dof]:.4f} mm against the closed form {1e3 * closed:.4f} mm",
            abs(static[tip_dof] / closed - 1) < 1e-3,
            "bearings at the tube mouth and at the inner root "
            "(models/telescoping.toml; Pan's one-point sleeve is the other reading, tested too); "
            "bound 0.1 %",
        ),
        Item(
            "Fig 5, full coupling fed the same motion",
            "prescribed torques/forces (Eq 43)",
            f"tip {_gap(full.tip_y, part.tip_y):.1e} m, mouth "
            f"{_gap(full.outer_tip_y, part.outer_tip_y):.1e} m "
            f"from the motion-driven model (peak {1e3 * peak:.2f} mm)",
            _gap(full.tip_y, part.tip_y) < 1e-3 * peak,
            "bound 0.1 % of the peak; the gap is O(dt^2) "
            "(tests/dynamics/fem/test_telescoping_full.py)",
        ),
        Item(
            "Fig 5, the needed torque and force fed back",
            "full coupling driven by forces",
            f"theta {_gap(replay.theta, full.theta):.1e} rad, W {_gap(replay.W, full.W):.1e} m, "
            "tip "
            f"{_gap(replay.tip_y, full.tip_y):.1e} m from the motion run",
            _gap(replay.tip_y, full.tip_y) < 1e-9,
            f"torque {full.torque.min():.1f} .. {full.torque.max():.1f} N m, force "
            f"{full.force.min():.1f} .. "
            f"{full.force.max():.1f} N; same grid, so the same discrete equations (bound 1e-9)",
        ),
    ]
    _time_plot(
        out_dir / "figures" / "fig5_telescoping.png",
        "Telescoping pair: W 0.1 -> 0.5 m, 60 deg in 0.6 s",
        "transverse displacement (mm)",
        [
            (part, part.tip_y, "-", "inner tip H, prescribed motion"),
            (replay, replay.tip_y, "--", "inner tip H, full coupling, torque/force fed back"),
            (part, part.outer_tip_y, "-", "tube mouth, prescribed motion"),
            (replay, replay.outer_tip_y, "--", "tube mouth, full coupling"),
        ],
    )
    return Section(
        "Fig 5: prismatic joint between two flexible links",
        f"`models/telescoping.toml`, {n} + {n} elements, dt = 1 ms.",
        items,
        ["figures/fig5_telescoping.png"],
    )


def _time_plot(path: Path, title: str, ylabel: str, curves: list) -> None:
    """Curves ``(result, values in m, style, label)`` against time, in mm."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 4.2), layout="constrained")
    ax = fig.subplots()
    for res, y, style, label in curves:
        ax.plot(res.t, 1e3 * np.asarray(y), style, label=label)
    ax.set_xlabel("t (s)")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=100)


def sections(out_dir: Path, reduced: bool) -> list[Section]:
    """Figs 1-5 in the paper's order."""
    out_dir = Path(out_dir)
    return [fig1(out_dir, reduced), fig2(), fig3(), fig4(out_dir, reduced), fig5(out_dir, reduced)]
