"""Shared fixtures: paths and a per-session cache folder for compiled code and tables."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "models" / "subedi3link.toml"


@pytest.fixture(scope="session", autouse=True)
def _cache_folder(tmp_path_factory):
    """Keep the on-disk cache inside the test session unless the caller set one."""
    if "FLEXCTRL_CACHE" not in os.environ:
        os.environ["FLEXCTRL_CACHE"] = str(tmp_path_factory.mktemp("flexctrl-cache"))
    yield


@pytest.fixture
def model_path() -> Path:
    return MODEL


@pytest.fixture
def root() -> Path:
    return ROOT
