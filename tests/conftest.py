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
