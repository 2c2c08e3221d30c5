"""Subedi, Tyapin, Hovland (2021): every table and figure of the paper, in its order.

``run(out_dir, reduced)`` returns the :class:`~flexctrl.reproduce.items.Section` list;
``flexctrl reproduce subedi --out DIR`` writes it as ``report.md`` and
``reproduction.json``.  The pieces: Tables 1-3 and Fig 1
(:mod:`~flexctrl.reproduce.subedi_tables`), Figs 2-7 (:mod:`~flexctrl.reproduce.subedi_modes`),
Figs 8-13 (:mod:`~flexctrl.reproduce.subedi_time`, runs in
:mod:`~flexctrl.reproduce.subedi_runs`), Fig 14 (:mod:`~flexctrl.reproduce.subedi_fft`).

``reduced`` keeps every code path with coarser angle grids (90 instead of 30 degrees for
the shape families, 45 instead of 10-15 for the frequency slices and maps) and shorter
runs (2 s of free vibration, which Fig 14 needs, 1 s of forced vibration), the
scheduled-modes runs in CasADi's virtual machine (on an empty library cache, as in CI,
compiling each took 30-50 s, more than the VM's run: 164 s for the four, against about
70 s in the VM).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from flexctrl.reproduce.items import Section
from flexctrl.spec.shipped import data_root

TITLE = (
    'Subedi, Tyapin, Hovland (2021), "Dynamic Modeling of Planar Multi-Link Flexible '
    'Manipulators", '
    "Robotics 10, 70"
)
MODEL = data_root() / "models" / "subedi3link.toml"
#: The paper's numbered tables and figures, in its order (the reproduction covers each).
NUMBERED = (
    "Fig 1",
    "Table 1",
    "Table 2",
    "Table 3",
    "Fig 2",
    "Fig 3",
    "Fig 4",
    "Fig 5",
    "Fig 6",
    "Fig 7",
    "Fig 8",
    "Fig 9",
    "Fig 10",
    "Fig 11",
    "Fig 12",
    "Fig 13",
    "Fig 14",
)


def run(out_dir: Path, reduced: bool = False) -> list[Section]:
    """Run the reproduction of Subedi et al. (2021); figures go to ``out_dir/figures``.

    Parameters
    ----------
    out_dir : Path
        Output directory (created).
    reduced : bool
        Coarser grids and shorter runs, same code paths (for CI).

    Returns
    -------
    list of Section
        In the paper's order: Fig 1, Tables 1-3, Figs 2-14, then the run times.
    """
    from flexctrl.dynamics.build import build_model
    from flexctrl.modal.identify import identify_hub_masses
    from flexctrl.reproduce import subedi_fft, subedi_modes, subedi_tables, subedi_time
    from flexctrl.reproduce.subedi_runs import Runs
    from flexctrl.spec.arm import load_arm

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    arm = load_arm(MODEL)
    fit = identify_hub_masses(arm)
    model = build_model(arm, "amm:2", reference_q=np.zeros(arm.n_links))
    family, slices, maps = (90.0, 45.0, 45.0) if reduced else (30.0, 5.0, 10.0)
    sections = [
        subedi_tables.fig1(arm, model, out_dir),
        subedi_tables.table1(arm),
        subedi_tables.table2(arm, fit),
        subedi_tables.table3(arm),
        subedi_modes.fig2(arm, out_dir),
        subedi_modes.fig3(arm, out_dir),
        subedi_modes.fig4(arm, out_dir, family),
        subedi_modes.fig5(arm, out_dir),
        subedi_modes.fig6(arm, out_dir, slices),
        subedi_modes.fig7(arm, out_dir, maps),
    ]
    modal_seconds = time.perf_counter() - start
    runs = Runs(reduced)
    sections += subedi_time.fig8_9(runs, out_dir)
    sections += subedi_time.fig10_11(runs, out_dir)
    sections += subedi_time.fig12_13(runs, out_dir)
    sections.append(subedi_fft.fig14(runs, out_dir))
    timing = ", ".join(
        f"{key} {variant} {seconds:.1f} s" for (key, variant), seconds in runs.seconds.items()
    )
    sections.append(
        Section(
            "Runs",
            f"Modal analysis (Tables 1-3, Figs 1-7) {modal_seconds:.1f} s. Simulations (build, "
            f"compile or cached library, run): {timing}.",
        )
    )
    return sections
