"""Pan, Scott & Ulsoy (1990), "Dynamic Modeling and Simulation of Flexible Robots With Prismatic
Joints": every figure of the paper in its order beside the toolkit's results.

The paper has no tables; its nine figures are five schematics of the formulation (Figs 1-5), the
example's geometry (Fig 6) and its three response plots (Figs 7-9), whose curves are not in the
text.  Each is set beside a run (:mod:`~flexctrl.reproduce.pan_joints` for Figs 1-5,
:mod:`~flexctrl.reproduce.pan_beam` for Figs 6-9); the claims of the numerical procedure (Sec. 4:
Baumgarte's gamma = beta = 5, the sign of Eq 54, the efficiency against Gear-type codes) follow in
:mod:`~flexctrl.reproduce.pan_numerics`.

``run(out_dir, reduced)`` returns the sections; ``reduced`` keeps every code path with coarser
meshes, fewer sweep points and shorter efficiency runs (for CI).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from flexctrl.reproduce.items import Section

TITLE = (
    "Pan, Scott and Ulsoy 1990, Dynamic Modeling and Simulation of Flexible Robots With "
    "Prismatic Joints, "
    "ASME J. Mech. Design 112, 307-314"
)


def run(out_dir: Path, reduced: bool) -> list[Section]:
    """Run the reproduction; figures are written into ``out_dir/figures`` (created).

    Returns
    -------
    list of Section
        Figs 1-9 in the paper's order, then Sec. 4's claims.
    """
    from flexctrl.reproduce import pan_beam, pan_joints, pan_numerics

    out_dir = Path(out_dir)
    (out_dir / "figures").mkdir(parents=True, exist_ok=True)
    sections = (
        pan_joints.sections(out_dir, reduced)
        + pan_beam.sections(out_dir, reduced)
        + pan_numerics.sections(out_dir, reduced)
    )
    for s in sections:  # verdicts computed with numpy are numpy booleans: JSON wants bool
        s.items = [dataclasses.replace(it, agrees=bool(it.agrees)) for it in s.items]
    return sections
