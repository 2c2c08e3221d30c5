"""Figures of the modal analysis (matplotlib, written to PNG files).

The figures a user of Subedi et al. (2021) would look for: mode shapes per link
with and without payload (Fig 2), the configuration-dependent boundary values
J_D1, M_D1, M_D2 over (q2, q3) (Fig 3), and frequency maps of links 1 and 2
over (q2, q3) (Figs 6-7), each with the exact and the paper's boundary inertia.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from flexctrl.modal.arm_modes import arm_modes, link_modes  # noqa: E402
from flexctrl.modal.boundary import boundary_values  # noqa: E402
from flexctrl.spec.arm import ArmSpec  # noqa: E402


def plot_mode_shapes(
    arm: ArmSpec, payloads: tuple[float, ...], path: Path, n_modes: int = 2
) -> Path:
    """Mode shapes phi_ij(x) of every link at the arm's configuration, one row per payload.

    Parameters
    ----------
    arm : ArmSpec
        The arm described.
    payloads : tuple of float
        Payload masses (kg), one row of plots each.
    path : pathlib.Path
        The PNG written.
    n_modes : int
        Modes per link plotted.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    fig, axes = plt.subplots(
        len(payloads), arm.n_links, figsize=(4 * arm.n_links, 3 * len(payloads)), squeeze=False
    )
    q = np.array(arm.configuration)
    for row, payload in enumerate(payloads):
        for link, modes in enumerate(arm_modes(arm.with_payload(payload), q, n_modes)):
            ax = axes[row, link]
            x = np.linspace(0.0, arm.links[link].length, 151)
            for j, shape in enumerate(modes.shape(x)):
                ax.plot(x, shape, label=f"mode {j + 1}: {modes.frequency_hz[j]:.2f} Hz")
            ax.set_title(f"link {link + 1}, payload {payload:g} kg")
            ax.set_xlabel("x (m)")
            ax.set_ylabel("phi (-)")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def configuration_grid(step_deg: float = 10.0) -> np.ndarray:
    """Angles (degrees) from -180 to 180 with ``step_deg``.

    Parameters
    ----------
    step_deg : float
        Grid step (degrees).

    Returns
    -------
    numpy.ndarray
        The angles (degrees).
    """
    return np.arange(-180.0, 180.0 + step_deg / 2, step_deg)


def plot_boundary_values(arm: ArmSpec, path: Path, step_deg: float = 10.0) -> Path:
    """J_D1 and M_D1 over (q2, q3) and M_D2 over q3, for both inertia conventions (3-link arms).

    Parameters
    ----------
    arm : ArmSpec
        The arm described.
    path : pathlib.Path
        The PNG written.
    step_deg : float
        Grid step (degrees).

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    grid = configuration_grid(step_deg)
    Q2, Q3 = np.meshgrid(grid, grid, indexing="ij")
    q = np.zeros(Q2.shape + (arm.n_links,))
    q[..., 1], q[..., 2] = np.radians(Q2), np.radians(Q3)
    exact = boundary_values(arm, q, 0, "exact")
    paper = boundary_values(arm, q, 0, "paper")
    fig, axes = plt.subplots(1, 4, figsize=(18, 4))
    for ax, data, title in (
        (axes[0], exact.J, "J_D1 exact (kg m^2)"),
        (axes[1], paper.J, "J_D1 paper Eq 70 (kg m^2)"),
        (axes[2], exact.M, "M_D1 (kg m)"),
    ):
        mesh = ax.pcolormesh(Q2, Q3, data, shading="auto")
        fig.colorbar(mesh, ax=ax)
        ax.set_title(title)
        ax.set_xlabel("q2 (deg)")
        ax.set_ylabel("q3 (deg)")
    q1d = np.zeros((grid.size, arm.n_links))
    q1d[:, 2] = np.radians(grid)
    axes[3].plot(grid, boundary_values(arm, q1d, 1).M, label="M_D2 (kg m)")
    axes[3].plot(grid, boundary_values(arm, q1d, 1).J, label="J_D2 (kg m^2)")
    axes[3].set_xlabel("q3 (deg)")
    axes[3].legend()
    axes[3].grid(True, alpha=0.3)
    fig.suptitle(f"Boundary values, payload {arm.payload.mass:g} kg")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def frequency_maps(
    arm: ArmSpec, step_deg: float = 15.0, convention: str | None = None
) -> dict[str, np.ndarray]:
    """f11, f12 over (q2, q3) and f21, f22 over q3 (Hz), by exact solves on a grid.

    Parameters
    ----------
    arm : ArmSpec
        The arm described.
    step_deg : float
        Grid step (degrees).
    convention : {"exact", "paper"}, optional
        Tip-inertia convention (default the arm's ``boundary_inertia``).

    Returns
    -------
    dict
        ``grid_deg`` (degrees), ``link1`` (Hz, shape (n, n, 2)), ``link2`` (Hz, shape (n, 2)).
    """
    grid = configuration_grid(step_deg)
    f1 = np.zeros((grid.size, grid.size, 2))
    f2 = np.zeros((grid.size, 2))
    for a, q2 in enumerate(grid):
        for b, q3 in enumerate(grid):
            q = np.radians([0.0, q2, q3])
            f1[a, b] = link_modes(arm, q, 0, 2, convention).frequency_hz
    for b, q3 in enumerate(grid):
        f2[b] = link_modes(arm, np.radians([0.0, 0.0, q3]), 1, 2, convention).frequency_hz
    return {"grid_deg": grid, "link1": f1, "link2": f2}


def plot_frequency_maps(arm: ArmSpec, path: Path, step_deg: float = 15.0) -> tuple[Path, dict]:
    """Frequency maps of links 1-2 with the exact and the paper's J_D, and their difference.

    Parameters
    ----------
    arm : ArmSpec
        The arm described.
    path : pathlib.Path
        The PNG written.
    step_deg : float
        Grid step (degrees).

    Returns
    -------
    tuple
        ``path`` and the exact convention's maps (:func:`frequency_maps`).
    """
    exact = frequency_maps(arm, step_deg, "exact")
    paper = frequency_maps(arm, step_deg, "paper")
    grid = exact["grid_deg"]
    Q2, Q3 = np.meshgrid(grid, grid, indexing="ij")
    fig, axes = plt.subplots(2, 4, figsize=(19, 8))
    for mode in range(2):
        for col, (data, title) in enumerate(
            ((exact["link1"][..., mode], "exact"), (paper["link1"][..., mode], "paper Eq 70"))
        ):
            ax = axes[mode, col]
            mesh = ax.pcolormesh(Q2, Q3, data, shading="auto")
            fig.colorbar(mesh, ax=ax, label="Hz")
            ax.set_title(f"f1{mode + 1} ({title})")
            ax.set_xlabel("q2 (deg)")
            ax.set_ylabel("q3 (deg)")
        ax = axes[mode, 2]
        diff = paper["link1"][..., mode] - exact["link1"][..., mode]
        mesh = ax.pcolormesh(Q2, Q3, diff, shading="auto", cmap="RdBu_r")
        fig.colorbar(mesh, ax=ax, label="Hz")
        ax.set_title(f"f1{mode + 1}: paper - exact")
        ax.set_xlabel("q2 (deg)")
        ax.set_ylabel("q3 (deg)")
        ax = axes[mode, 3]
        ax.plot(grid, exact["link2"][:, mode], label="exact")
        ax.plot(grid, paper["link2"][:, mode], "--", label="paper Eq 70")
        ax.set_title(f"f2{mode + 1} over q3")
        ax.set_xlabel("q3 (deg)")
        ax.set_ylabel("Hz")
        ax.legend()
        ax.grid(True, alpha=0.3)
    fig.suptitle(f"Natural frequencies, payload {arm.payload.mass:g} kg")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    worst = {
        "link1_max_abs_diff_hz": float(np.max(np.abs(paper["link1"] - exact["link1"]))),
        "link2_max_abs_diff_hz": float(np.max(np.abs(paper["link2"] - exact["link2"]))),
    }
    return path, worst
