"""Subedi et al. (2021), Figs 2-7: mode shapes and frequencies against payload and configuration.

The paper's argument that the modes depend on the configuration: Fig 2 (payload), Fig 3
(the boundary values J_D1, M_D1, M_D2), Fig 4 (families of shapes over q2, q3), Fig 5 (the
arm drawn with its shapes), Fig 6 (1-D frequency slices at 0/90/180 deg) and Fig 7 (maps).
The paper prints no numbers for them; each item tests a behaviour its text states.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib
import numpy as np

from flexctrl.modal.arm_modes import link_modes
from flexctrl.modal.boundary import boundary_values
from flexctrl.modal.mode_plots import (
    frequency_maps,
    plot_boundary_values,
    plot_frequency_maps,
    plot_mode_shapes,
)
from flexctrl.modal.paper_data import SUBEDI_TABLE3_HZ
from flexctrl.reproduce.drawing import figure, save
from flexctrl.reproduce.items import Item, Section
from flexctrl.spec.arm import ArmSpec

X_STEP = 0.01  # m, the paper's mode-shape step (Section 4.1)
#: A shape or frequency "changes" when it moves by more than this fraction (well above the
#: eigensolver's 1e-10 and far below the changes the paper draws).
CHANGE = 1e-6


def _shapes(arm: ArmSpec, q_deg, link: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """x (m), the two shapes (2, len(x)) and the frequencies (Hz) of ``link`` (0-based) at
    ``q_deg``."""
    x = np.arange(0.0, arm.links[link].length + X_STEP / 2, X_STEP)
    modes = link_modes(arm, np.radians(q_deg), link, 2)
    return x, modes.shape(x), modes.frequency_hz


def _aligned(shape: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """``shape`` with each mode's sign chosen to overlap ``ref`` (eigenvectors have no sign)."""
    signs = np.sign(np.sum(shape * ref, axis=1))
    return shape * np.where(signs == 0, 1.0, signs)[:, None]


def shape_change(arm: ArmSpec, link: int, poses) -> float:
    """Largest change of ``link``'s shapes over ``poses`` (degrees), relative to the first pose's
    peak."""
    _x, ref, _f = _shapes(arm, poses[0], link)
    worst = 0.0
    for pose in poses[1:]:
        _x, shape, _f = _shapes(arm, pose, link)
        worst = max(worst, float(np.max(np.abs(_aligned(shape, ref) - ref)) / np.max(np.abs(ref))))
    return worst


def fig2(arm: ArmSpec, out_dir: Path) -> Section:
    """Fig 2: shapes at 0 and 2 kg; the paper: the payload changes link 3's shapes most."""
    path = Path(out_dir) / "figures" / "fig02_mode_shapes.png"
    path.parent.mkdir(parents=True, exist_ok=True)
    plot_mode_shapes(arm, (0.0, 2.0), path)
    change = []
    for link in range(3):
        _x, a, _f = _shapes(arm.with_payload(0.0), (0, 0, 0), link)
        _x, b, _f = _shapes(arm.with_payload(2.0), (0, 0, 0), link)
        change.append(float(np.max(np.abs(_aligned(b, a) - a)) / np.max(np.abs(a))))
    item = Item(
        "Fig 2, payload effect on shapes",
        "more evident on link 3 than on links 1 and 2",
        "largest shape change 0 -> 2 kg: "
        + ", ".join(f"link {i + 1} {100 * c:.1f} %" for i, c in enumerate(change)),
        int(np.argmax(change)) == 2,
        "max |phi(2 kg) - phi(0 kg)| / max |phi(0 kg)|, both modes, q2 = q3 = 0",
    )
    return Section(
        "Fig 2: mode shapes with no payload and the nominal payload",
        "Shapes normalised by Eq 40 (dimensionless), sampled every 0.01 m as in Section 4.1.",
        [item],
        ["figures/fig02_mode_shapes.png"],
    )


def fig3(arm: ArmSpec, out_dir: Path) -> Section:
    """Fig 3: J_D1 depends on q3 only, M_D1 on q2 and q3, M_D2 on q3 only (Eqs 69-71)."""
    path = Path(out_dir) / "figures" / "fig03_boundary_values.png"
    plot_boundary_values(arm, path)
    grid = np.radians(np.arange(-180.0, 181.0, 30.0))
    Q2, Q3 = np.meshgrid(grid, grid, indexing="ij")
    q = np.stack([np.zeros_like(Q2), Q2, Q3], axis=-1)
    items = []
    for conv in ("exact", "paper"):
        b1, b2 = boundary_values(arm, q, 0, conv), boundary_values(arm, q, 1, conv)

        def spread(v, axis):  # the range over one joint
            return float(np.max(np.ptp(v, axis=axis)))

        checks = (
            (
                "J_D1",
                b1.J,
                "q3 only",
                spread(b1.J, 0) < CHANGE and spread(b1.J, 1) > CHANGE,
                "kg m^2",
            ),
            (
                "M_D1",
                b1.M,
                "q2 and q3",
                spread(b1.M, 0) > CHANGE and spread(b1.M, 1) > CHANGE,
                "kg m",
            ),
            (
                "M_D2",
                b2.M,
                "q3 only",
                spread(b2.M, 0) < CHANGE and spread(b2.M, 1) > CHANGE,
                "kg m",
            ),
        )
        for name, value, says, ok, unit in checks:
            items.append(
                Item(
                    f"Fig 3, {name} ({conv} J_D)",
                    f"depends on {says}",
                    f"range over q2 {spread(value, 0):.3g} {unit}, over q3 "
                    f"{spread(value, 1):.3g} {unit}; "
                    f"{value.min():.3f} to {value.max():.3f} {unit}",
                    ok,
                )
            )
    text = (
        "Two readings of J_D (Eq 69): the rigid-body moment of inertia about the link tip "
        "(`exact`, the model "
        "file's choice) and Eq 70's projected distances (`paper`, e.g. d_l32 = l2 + l3/2 cos "
        "q3). They agree "
        "at q3 = 0 and 180 deg, so Table 3 cannot tell them apart; both are drawn."
    )
    return Section(
        "Fig 3: boundary values J_D1, M_D1, M_D2 (2 kg)",
        text,
        items,
        ["figures/fig03_boundary_values.png"],
    )


def fig4(arm: ArmSpec, out_dir: Path, step: float) -> Section:
    """Fig 4: families of shapes: link 1 over q2 (q3 = 0) and over q3 (q2 = 0), link 2 over q3."""
    angles = np.arange(-180.0, 180.0 + step / 2, step)
    cases = (
        ("a", 0, 1, "link 1 over q2, q3 = 0"),
        ("b", 0, 2, "link 1 over q3, q2 = 0"),
        ("c", 1, 2, "link 2 over q3"),
    )
    fig, axes = figure(2, 3, 4.3, 3.0)
    items = []
    cmap = matplotlib.colormaps["viridis"]
    for col, (panel, link, joint, title) in enumerate(cases):
        poses = [tuple(a if k == joint else 0.0 for k in range(3)) for a in angles]
        _x, ref, _f = _shapes(arm, poses[0], link)
        for pose, angle in zip(poses, angles):
            x, shape, freq = _shapes(arm, pose, link)
            shape = _aligned(shape, ref)
            for mode in range(2):
                axes[mode, col].plot(
                    x,
                    shape[mode],
                    color=cmap((angle + 180) / 360),
                    lw=1,
                    label=f"{angle:+.0f} deg" if mode == 0 else None,
                )
        for mode in range(2):
            axes[mode, col].set_title(f"Fig 4{panel}: {title}, mode {mode + 1}", fontsize=9)
            axes[mode, col].set_xlabel("x (m)")
            axes[mode, col].set_ylabel("phi (-)")
        change = shape_change(arm, link, poses)
        items.append(
            Item(
                f"Fig 4{panel}, {title}",
                "the shapes change with the angle",
                f"largest change {100 * change:.2f} %",
                change > CHANGE,
                "max |phi - phi(-180 deg)| / max |phi(-180 deg)| over the family",
            )
        )
    axes[0, 0].legend(fontsize=6, ncol=2)
    fixed = (("link 2 over q2", 1, 1), ("link 3 over q2", 2, 1), ("link 3 over q3", 2, 2))
    for title, link, joint in fixed:
        change = shape_change(
            arm, link, [tuple(a if k == joint else 0.0 for k in range(3)) for a in angles]
        )
        items.append(
            Item(f"Fig 4, {title}", "unchanged", f"largest change {change:.1e}", change < CHANGE)
        )
    return Section(
        "Fig 4: mode shapes against the configuration (2 kg)",
        f"Families every {step:g} deg from -180 to "
        "180 deg (+a and -a give the same shapes: Eqs 69-70 hold only cosines), the sign of each "
        "shape aligned "
        "to the first (an eigenvector has none).",
        items,
        [save(fig, out_dir, "fig04_shape_families.png")],
    )


def _draw_arm(ax, arm: ArmSpec, q_deg, scale: float) -> None:
    """Links as thick dashed lines, their two shapes as thin lines off each link (Fig 5's style)."""
    colours = ("tab:red", "tab:green", "tab:blue")
    origin, angle = np.zeros(2), 0.0
    for link in range(3):
        angle += math.radians(q_deg[link])
        x, shape, _f = _shapes(arm, q_deg, link)
        c, s = math.cos(angle), math.sin(angle)
        ax.plot(
            origin[0] + c * x,
            origin[1] + s * x,
            "--",
            color=colours[link],
            lw=2.5,
            label=f"link {link + 1}",
        )
        for mode, style in ((0, "-"), (1, "--")):
            d = scale * shape[mode]
            ax.plot(
                origin[0] + c * x - s * d,
                origin[1] + s * x + c * d,
                style,
                color=colours[link],
                lw=0.9,
            )
        ax.annotate("", origin + 0.4 * np.array([c, s]), origin, arrowprops={"arrowstyle": "->"})
        ax.annotate("", origin + 0.4 * np.array([-s, c]), origin, arrowprops={"arrowstyle": "->"})
        origin = origin + arm.links[link].length * np.array([c, s])


def fig5(arm: ArmSpec, out_dir: Path) -> Section:
    """Fig 5: the arm drawn with its shapes at q3 (a) or q2 (b) = 0, 90, 180 deg, one pose per
    panel."""
    fig, axes = figure(2, 3, 4.2, 3.3)
    items = []
    for row, (panel, joint) in enumerate((("a", 2), ("b", 1))):
        poses = [tuple(a if k == joint else 0.0 for k in range(3)) for a in (0.0, 90.0, 180.0)]
        for col, (pose, tag) in enumerate(zip(poses, ("I", "II", "III"))):
            ax = axes[row, col]
            _draw_arm(ax, arm, pose, 0.3)
            ax.set_aspect("equal")
            ax.set(xlabel="X0 (m)", ylabel="Y0 (m)", xlim=(-1.8, 4.8), ylim=(-1.0, 3.3))
            ax.set_title(
                f"Fig 5{panel} [{tag}]: q{joint + 1} = {pose[joint]:g} deg (shapes x 0.3 m)",
                fontsize=9,
            )
        change = [shape_change(arm, link, poses) for link in range(3)]
        expect = [True, True, False] if joint == 2 else [True, False, False]
        says = (
            "links 1 and 2 change, link 3 does not"
            if joint == 2
            else "link 1 changes, links 2 and 3 do not"
        )
        items.append(
            Item(
                f"Fig 5{panel}, q{joint + 1} = 0/90/180 deg",
                says,
                ", ".join(f"link {i + 1} {100 * c:.2f} %" for i, c in enumerate(change)),
                [c > CHANGE for c in change] == expect,
                "the paper's text for 5b says 'with the change in q_r3', a slip for q_r2 (its "
                "own caption)"
                if joint == 1
                else "",
            )
        )
    axes[0, 0].legend(fontsize=7)
    return Section(
        "Fig 5: the arm with its mode shapes (2 kg)",
        "Links thick dashed (1 red, 2 green, 3 blue), first "
        "modes thin solid, second modes thin dashed, joint frames (X_i, Y_i) as arrows, as in "
        "the paper; "
        "the paper overlays [I]-[III] in one panel, here each pose has its own.",
        items,
        [save(fig, out_dir, "fig05_arm_shapes.png")],
    )


def fig6(arm: ArmSpec, out_dir: Path, step: float) -> Section:
    """Fig 6: f11, f12, f21, f22 against q3 at q2 = 0/90/180 (a, c, e) and against q2 at
    q3 = 0/90/180 (b, d, f)."""
    angles = np.arange(-180.0, 180.0 + step / 2, step)
    fig, axes = figure(3, 2, 5.0, 3.0)
    items = []
    for row, fixed in enumerate((0.0, 90.0, 180.0)):
        for col, (vary, hold) in enumerate(((2, 1), (1, 2))):
            panel = "abcdef"[2 * row + col]
            freqs = _slice_frequencies(arm, angles, vary, fixed)
            _draw_slice(axes[row, col], angles, freqs, row == 0 and col == 0)
            axes[row, col].set_xlabel(f"q{vary + 1} (deg)")
            axes[row, col].set_ylabel("frequency (Hz)")
            axes[row, col].set_title(f"Fig 6{panel}: q{hold + 1} = {fixed:g} deg", fontsize=9)
            items.append(_slice_item(freqs, panel, vary, hold, fixed))
    axes[0, 0].legend(fontsize=6, ncol=2)
    at_zero = np.array([link_modes(arm, np.zeros(3), link, 2).frequency_hz for link in range(3)])
    ref = np.array(SUBEDI_TABLE3_HZ[arm.payload.mass])
    items.append(
        Item(
            "Fig 6, link 3 at every pose",
            "constant, equal to Table 3 (2 kg)",
            f"{at_zero[2, 0]:.3f}, {at_zero[2, 1]:.3f} Hz at every pose (link 3's boundary is "
            "the payload alone)",
            bool(np.all(np.abs(at_zero[2] - ref[2]) < 0.005))
            and shape_change(arm, 2, [(0, 0, 0), (0, 90, 45)]) < CHANGE,
        )
    )
    return Section(
        "Fig 6: eigenfrequencies of links 1 and 2 along slices (2 kg)",
        f"Every {step:g} deg; solid: exact "
        "J_D (the model's), dotted: Eq 70's projected J_D (link 2's J_D has no projection, so "
        "its two lines coincide).",
        items,
        [save(fig, out_dir, "fig06_frequency_slices.png")],
    )


def _slice_frequencies(arm: ArmSpec, angles, vary: int, fixed: float) -> dict[str, np.ndarray]:
    """Links 1 and 2's two frequencies (Hz) along a slice, with the exact and Eq 70's J_D."""
    freqs = {}
    for conv in ("exact", "paper"):
        freqs[conv] = np.array(
            [
                [
                    link_modes(
                        arm,
                        np.radians([0.0] + [a if k == vary else fixed for k in (1, 2)]),
                        link,
                        2,
                        conv,
                    ).frequency_hz
                    for link in (0, 1)
                ]
                for a in angles
            ]
        )
    return freqs


def _draw_slice(ax, angles, freqs: dict[str, np.ndarray], label: bool) -> None:
    for conv, style in (("exact", "-"), ("paper", ":")):
        f = freqs[conv]
        for link in (0, 1):
            for mode in range(2):
                ax.plot(
                    angles,
                    f[:, link, mode],
                    style,
                    lw=1,
                    color=f"C{2 * link + mode}",
                    label=f"f{link + 1}{mode + 1} ({conv})" if label else None,
                )


def _slice_item(freqs, panel: str, vary: int, hold: int, fixed: float) -> Item:
    """Which links' frequencies change along the slice, against what the paper says."""
    f = freqs["exact"]
    rng1, rng2 = np.ptp(f[:, 0, :], axis=0), np.ptp(f[:, 1, :], axis=0)
    if vary == 1:
        says = "link 1 changes with q2; link 2 does not"
        ok = bool(np.all(rng1 > CHANGE) and np.all(rng2 < CHANGE))
    else:
        says = "links 1 and 2 change with q3"
        ok = bool(np.all(rng1 > CHANGE) and np.all(rng2 > CHANGE))
    return Item(
        f"Fig 6{panel}, q{hold + 1} = {fixed:g} deg",
        says,
        f"range of f11, f12: {rng1[0]:.3f}, {rng1[1]:.3f} Hz; f21, f22: "
        f"{rng2[0]:.3g}, {rng2[1]:.3g} Hz",
        ok,
        f"Eq 70 J_D differs from exact by up to "
        f"{np.max(np.abs(freqs['paper'] - freqs['exact'])):.2f} Hz on this slice",
    )


def fig7(arm: ArmSpec, out_dir: Path, step: float) -> Section:
    """Fig 7: maps of f11, f12 over (q2, q3) and f21, f22 over q3; symmetric under (q2, q3) -> (-q2,
    -q3)."""
    path = Path(out_dir) / "figures" / "fig07_frequency_maps.png"
    _path, diff = plot_frequency_maps(arm, path, step)
    maps = frequency_maps(arm, step)
    f1 = maps["link1"]
    mirror = float(np.max(np.abs(f1 - f1[::-1, ::-1])))
    items = [
        Item(
            "Fig 7a-b, f11 and f12 over (q2, q3)",
            "vary over the whole (q2, q3) plane",
            f"f11 {f1[..., 0].min():.3f} to {f1[..., 0].max():.3f} Hz, f12 "
            f"{f1[..., 1].min():.2f} to "
            f"{f1[..., 1].max():.2f} Hz; mirror symmetry f(q2, q3) = f(-q2, -q3) to {mirror:.1e} "
            "Hz",
            bool(np.ptp(f1[..., 0]) > CHANGE and mirror < 1e-6),
            "symmetry: Eqs 69-70 hold only cosines",
        ),
        Item(
            "Fig 7c, f22 over q3",
            "varies with q3",
            f"{maps['link2'][:, 1].min():.2f} to {maps['link2'][:, 1].max():.2f} Hz",
            bool(np.ptp(maps["link2"][:, 1]) > CHANGE),
            f"Eq 70's J_D moves link 1 by up to {diff['link1_max_abs_diff_hz']:.2f} Hz, link 2 by "
            f"{diff['link2_max_abs_diff_hz']:.2f} Hz",
        ),
    ]
    return Section(
        "Fig 7: eigenfrequency maps of links 1 and 2 (2 kg)",
        f"Grid step {step:g} deg; exact and Eq 70 J_D side by side with their difference.",
        items,
        ["figures/fig07_frequency_maps.png"],
    )
