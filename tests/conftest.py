"""Fixtures shared by the tests: paths and small plants (the Agg backend is set in the repository's
conftest.py)."""

from __future__ import annotations

from pathlib import Path

import pytest
from support import DATA, MODEL, ROOT


@pytest.fixture
def model_path() -> Path:
    return MODEL


@pytest.fixture
def root() -> Path:
    """The shipped description files (``models/``, ``controllers/``, ``studies/``)."""
    return DATA


@pytest.fixture
def selftest_study(tmp_path) -> Path:
    """``tests/data/study_selftest.toml`` and its files copied to ``tmp_path`` (isolated from edits
    of models/)."""
    import shutil

    shutil.copytree(ROOT / "tests" / "data", tmp_path / "tests" / "data")
    (tmp_path / "models").mkdir()
    shutil.copy(MODEL, tmp_path / "models")
    return tmp_path / "tests" / "data" / "study_selftest.toml"


@pytest.fixture(scope="module")
def onelink():
    """A one-link arm with one assumed mode (4 states) and its equilibrium at 0.5 rad: the NMPC
    tests' small plant."""
    from flexctrl import linear as L
    from flexctrl.dynamics.amm import build_amm
    from flexctrl.spec.arm import arm_from_document

    doc = {
        "name": "onelink",
        "gravity": [0.0, -9.81],
        "payload": {"mass": 0.5, "inertia": 1e-3},
        "links": [
            {
                "length": 1.0,
                "mass_per_length": 1.5,
                "EI": 400.0,
                "inertia": 1.5 / 12,
                "n_modes": 1,
                "damping_ratio": 0.02,
            }
        ],
        "joints": [{"hub_mass": 0.0, "hub_inertia": 0.05, "torque_limit": 15.0}],
    }
    model = build_amm(arm_from_document(doc, "onelink.toml"), 1)
    return model, L.equilibrium(model, [0.5])
