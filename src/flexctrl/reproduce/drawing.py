"""Small drawing helpers of the reproductions: a figure without pyplot state, and its file."""

from __future__ import annotations

from pathlib import Path

from matplotlib.figure import Figure


def figure(rows: int = 1, cols: int = 1, width: float = 4.2, height: float = 3.2):
    """A matplotlib Figure (Agg, no pyplot state) and its axes as a 2-D array."""
    fig = Figure(figsize=(width * cols, height * rows))
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.flat:
        ax.grid(True, alpha=0.3)
    return fig, axes


def save(fig: Figure, out_dir: Path, name: str) -> str:
    """Write ``out_dir/figures/name`` (PNG) and return its path relative to ``out_dir``."""
    folder = Path(out_dir) / "figures"
    folder.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(folder / name, dpi=90)
    return f"figures/{name}"
