"""The example study of the study tests, copied to a temporary folder."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from support import DATA as SHIPPED
from support import ROOT

TEST_DATA = ROOT / "tests" / "data"


@pytest.fixture
def study(tmp_path, root) -> Path:
    """The example study and its files copied to tmp_path (isolated from edits of models/)."""
    shutil.copytree(TEST_DATA, tmp_path / "tests" / "data")
    (tmp_path / "models").mkdir()
    shutil.copy(SHIPPED / "models" / "subedi3link.toml", tmp_path / "models")
    return tmp_path / "tests" / "data" / "study_selftest.toml"
