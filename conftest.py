"""pytest set-up shared by the test suite and the doctests of the package (run from the repository root)."""

from __future__ import annotations

import os

import matplotlib
import pytest

matplotlib.use("Agg")


@pytest.fixture(scope="session", autouse=True)
def _cache_folder(tmp_path_factory):
    """Keep the on-disk cache of compiled code inside the test session unless the caller set one."""
    if "FLEXCTRL_CACHE" not in os.environ:
        os.environ["FLEXCTRL_CACHE"] = str(tmp_path_factory.mktemp("flexctrl-cache"))
    yield
