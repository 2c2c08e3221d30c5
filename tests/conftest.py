"""Paths shared by the tests (the Agg backend and the cache folder are set in the repository's conftest.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "models" / "subedi3link.toml"


@pytest.fixture
def model_path() -> Path:
    return MODEL


@pytest.fixture
def root() -> Path:
    return ROOT


@pytest.fixture
def selftest_study(tmp_path) -> Path:
    """``tests/data/study_selftest.toml`` and its files copied to ``tmp_path`` (isolated from edits of models/)."""
    import shutil

    shutil.copytree(ROOT / "tests" / "data", tmp_path / "tests" / "data")
    (tmp_path / "models").mkdir()
    shutil.copy(MODEL, tmp_path / "models")
    return tmp_path / "tests" / "data" / "study_selftest.toml"
