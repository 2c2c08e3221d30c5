"""Paths shared by the tests: the repository and the shipped description files."""

from pathlib import Path

import numpy as np

import flexctrl as fc
from flexctrl.spec.shipped import data_root

#: The repository (the tests, docs and README live here).
ROOT = Path(__file__).resolve().parents[1]
#: The shipped models, controllers, scenes and studies (package data).
DATA = data_root()
#: The three-link arm of Subedi et al. (2021).
MODEL = DATA / "models" / "subedi3link.toml"


def scene_arm(
    payload: float = 2.0,
    fidelity: str = "amm:2",
    start_deg: tuple[float, ...] | None = (0.0, 0.0, 90.0),
    zeta: float = 0.005,
):
    """The move scenes' arm at ``payload`` kg: horizontal, structural damping ratio ``zeta`` on
    every link, modes frozen at the move's start ``start_deg`` (degrees; None: the file's
    configuration)."""
    return fc.load_model(
        "subedi3link",
        payload=payload,
        fidelity=fidelity,
        gravity=[0.0, 0.0],
        overrides={f"links[{i}].damping_ratio": zeta for i in (1, 2, 3)},
        reference_q=None if start_deg is None else np.radians(start_deg),
    )
