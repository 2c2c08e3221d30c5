"""Execute every notebook in ``studies/notebooks`` with nbclient; any cell error fails the test.

The kernel is ipykernel on the interpreter running pytest (``sys.executable``), so the
notebooks see the same virtual environment and the same installed flexctrl, whatever
kernel specs happen to be installed for the user or the system (a ``python3`` spec in
``~/.local/share/jupyter`` would otherwise win over the venv's own).  Each notebook runs
with its own folder as the working directory, as in Jupyter; notebooks are read, never
written.  The kernel inherits the environment, including the session's ``FLEXCTRL_CACHE``
set in ``conftest.py``, and ``FLEXCTRL_NOTEBOOK_QUICK=1``: each notebook then runs the same
steps on a reduced grid (fewer payloads or models, amm:1, shorter runs), which keeps the three
notebooks to about a minute or two together on two cores.  Without it (Jupyter) they run in full,
a few minutes of CPU each.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import pytest

nbformat = pytest.importorskip(
    "nbformat", reason="notebook tests need the 'notebooks' extra (nbformat)"
)
nbclient = pytest.importorskip(
    "nbclient", reason="notebook tests need the 'notebooks' extra (nbclient)"
)
pytest.importorskip("ipykernel", reason="notebook tests need the 'notebooks' extra (ipykernel)")

from jupyter_client.kernelspec import KernelSpec, KernelSpecManager  # noqa: E402  (nbclient depends on it)
from jupyter_client.manager import AsyncKernelManager  # noqa: E402
from support import DATA, ROOT  # noqa: E402

NOTEBOOKS = sorted((DATA / "studies" / "notebooks").glob("*.ipynb"))
TIMEOUT_S = 600  # per cell


class ThisInterpreterKernelSpecs(KernelSpecManager):
    """Resolve every kernel name to ipykernel on ``sys.executable`` (no installed kernel spec
    needed)."""

    def get_kernel_spec(self, kernel_name: str) -> KernelSpec:
        return KernelSpec(
            argv=[sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
            display_name=f"Python 3 ({sys.executable})",
            language="python",
            resource_dir=str(ROOT),
        )


def execute_notebook(path: Path) -> tuple[object, float]:
    """Run all cells of ``path`` in a fresh kernel; return the executed notebook and the wall time
    (s)."""
    nb = nbformat.read(path, as_version=4)
    km = AsyncKernelManager(kernel_name="python3", kernel_spec_manager=ThisInterpreterKernelSpecs())
    client = nbclient.NotebookClient(
        nb,
        km=km,
        timeout=TIMEOUT_S,
        kernel_name="python3",
        resources={"metadata": {"path": str(path.parent)}},
    )
    start = time.perf_counter()
    client.execute()
    return nb, time.perf_counter() - start


@pytest.mark.skipif(not NOTEBOOKS, reason="no notebooks in studies/notebooks")
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes(path: Path, monkeypatch) -> None:
    monkeypatch.setenv("FLEXCTRL_NOTEBOOK_QUICK", "1")  # inherited by the kernel
    try:
        nb, _elapsed = execute_notebook(path)
    except nbclient.exceptions.CellExecutionError as exc:
        pytest.fail(f"{path.relative_to(ROOT)}: a cell raised an error:\n{exc}", pytrace=False)
    errors = [
        out
        for cell in nb.cells
        if cell.cell_type == "code"
        for out in cell.get("outputs", [])
        if out.get("output_type") == "error"
    ]
    assert not errors, f"{path.relative_to(ROOT)}: error outputs {[e.get('ename') for e in errors]}"


def test_notebooks_use_the_public_api_only() -> None:
    """``import flexctrl as fc`` and nothing deeper: the notebooks teach the API a user has."""
    assert len(NOTEBOOKS) >= 3
    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        code = "\n".join(cell.source for cell in nb.cells if cell.cell_type == "code")
        assert "import flexctrl as fc" in code, path.name
        deep = [
            line
            for line in code.splitlines()
            if "from flexctrl" in line or "import flexctrl." in line
        ]
        assert not deep, f"{path.name}: deep imports {deep}"
        assert "FLEXCTRL_NOTEBOOK_QUICK" in code, f"{path.name}: no reduced mode for the tests"


def test_notebooks_are_saved_without_outputs() -> None:
    """Notebooks are committed with cleared outputs, so diffs show only source changes."""
    dirty = []
    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        if any(
            cell.cell_type == "code" and (cell.get("outputs") or cell.get("execution_count"))
            for cell in nb.cells
        ):
            dirty.append(str(path.relative_to(ROOT)))
    assert not dirty, f"clear the outputs before saving: {dirty}"
