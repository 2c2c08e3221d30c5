"""PNG plots of a :class:`~flexctrl.sim.trajectory.Trajectory` (matplotlib Agg, no pyplot).

Four files, laid out like Figures 8-13 of Subedi et al. (2021): ``joints.png``
(joint angles, degrees), ``deflections.png`` (one panel per link: its tip
deflection and modal coordinates), ``tip.png`` (tip path and tip coordinates
against time) and ``energies.png`` (kinetic, elastic, gravitational and total).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from flexctrl.sim.trajectory import Trajectory


def _figure(rows: int = 1, cols: int = 1, height: float = 3.0):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, max(2.6, height * rows)), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, cols, squeeze=False)
    return fig, axes


def plot_trajectory(traj: Trajectory, directory: Path, prefix: str = "") -> list[Path]:
    """Write the four PNGs into ``directory``; returns their paths.

    Parameters
    ----------
    traj : Trajectory
        The simulated trajectory.
    directory : pathlib.Path
        Folder written to (made if missing).
    prefix : str
        Prefix of the file names.

    Returns
    -------
    list of pathlib.Path
        The files written.
    """
    directory.mkdir(parents=True, exist_ok=True)
    t = traj.time
    n_u = traj.inputs.shape[1]
    n_links = traj.deflections.shape[1]
    paths = []
    title = traj.meta.get("scene") or traj.meta.get("model", "")

    fig, ax = _figure()
    for j in range(n_u):
        ax[0, 0].plot(t, np.degrees(traj.q[:, j]), label=traj.coordinate_names[j])
    ax[0, 0].set(xlabel="t (s)", ylabel="joint angle (deg)", title=f"{title} joint positions")
    ax[0, 0].legend(loc="best")
    ax[0, 0].grid(True, alpha=0.3)
    paths.append(_save(fig, directory / f"{prefix}joints.png"))

    fig, ax = _figure(n_links, 1, height=2.2)
    for i in range(n_links):
        a = ax[i, 0]
        a.plot(t, 1e3 * traj.deflections[:, i], "k", lw=1.2, label=f"w{i + 1} (tip)")
        for j, name in enumerate(traj.coordinate_names):
            if name.startswith(f"qf{i + 1}") and len(name) > 3:
                a.plot(t, 1e3 * traj.q[:, j], lw=0.8, label=f"{name} (modal)")
        a.set(ylabel=f"link {i + 1} (mm)")
        a.legend(loc="upper right", fontsize="small")
        a.grid(True, alpha=0.3)
    ax[-1, 0].set(xlabel="t (s)")
    ax[0, 0].set_title(f"{title} link deflections")
    paths.append(_save(fig, directory / f"{prefix}deflections.png"))

    fig, ax = _figure(1, 2, height=3.2)
    ax[0, 0].plot(traj.tip[:, 0], traj.tip[:, 1], lw=0.8)
    ax[0, 0].plot(traj.tip[0, 0], traj.tip[0, 1], "go", label="start")
    ax[0, 0].plot(traj.tip[-1, 0], traj.tip[-1, 1], "rs", label="end")
    ax[0, 0].set(xlabel="x (m)", ylabel="y (m)", title="tip path")
    ax[0, 0].legend(loc="best", fontsize="small")
    ax[0, 1].plot(t, traj.tip[:, 0], label="tip_x")
    ax[0, 1].plot(t, traj.tip[:, 1], label="tip_y")
    ax[0, 1].set(xlabel="t (s)", ylabel="tip position (m)", title="tip position")
    ax[0, 1].legend(loc="best", fontsize="small")
    for a in ax[0]:
        a.grid(True, alpha=0.3)
    paths.append(_save(fig, directory / f"{prefix}tip.png"))

    fig, ax = _figure(2, 1, height=2.6)
    ax[0, 0].plot(t, traj.energies["E_el"], label="E_el")
    ax[0, 0].set(ylabel="elastic energy (J)", title=f"{title} energies")
    ax[0, 0].legend(loc="best", fontsize="small")
    for key in ("E_kin", "E_grav", "E_total"):
        ax[1, 0].plot(t, traj.energies[key], label=key)
    ax[1, 0].set(xlabel="t (s)", ylabel="energy (J)")
    ax[1, 0].legend(loc="best", fontsize="small")
    for a in ax[:, 0]:
        a.grid(True, alpha=0.3)
    paths.append(_save(fig, directory / f"{prefix}energies.png"))
    return paths


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=110)
    return path
