"""The wheel built from the checkout works from any folder once installed in a fresh venv.

The wheel is built from a copy of the checkout's ``pyproject.toml``, ``README.md`` and
``src/`` (so the build writes nothing into the checkout), installed without its dependencies
into a new venv that finds them through a ``.pth`` file naming this interpreter's
site-packages (nothing is downloaded), and used from a temporary folder outside the
repository: the public API loads a shipped model by name and the command line runs a shipped
study by name.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import sysconfig
import zipfile
from importlib.metadata import version
from pathlib import Path

import pytest
from support import DATA, ROOT

#: Kinds of shipped files and the folder of the wheel that holds each.
KINDS = {
    "models": "flexctrl/data/models/",
    "controllers": "flexctrl/data/controllers/",
    "scenes": "flexctrl/data/studies/scenes/",
    "studies": "flexctrl/data/studies/",
    "tunings": "flexctrl/data/studies/tuning/",
    "notebooks": "flexctrl/data/studies/notebooks/",
}


def _run(argv: list[str], cwd: Path) -> subprocess.CompletedProcess:
    done = subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"{argv}: {done.stderr[-2000:]}"
    return done


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel of the checkout, built without build isolation (offline) when it can be."""
    source = tmp_path_factory.mktemp("source")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, source)
    shutil.copytree(
        ROOT / "src" / "flexctrl",
        source / "src" / "flexctrl",
        ignore=shutil.ignore_patterns("__pycache__", "*.pyc"),
    )
    dist = tmp_path_factory.mktemp("dist")
    build = [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(dist), "."]
    # pyproject asks for setuptools >= 77; an older one here means an isolated build (online)
    if int(version("setuptools").split(".")[0]) >= 77:
        build[5:5] = ["--no-build-isolation", "--no-index"]
    _run(build, source)
    (found,) = dist.glob("flexctrl-*.whl")
    return found


@pytest.fixture(scope="module")
def fresh_venv(tmp_path_factory, wheel) -> Path:
    """A new venv with the wheel installed and this interpreter's packages on its path."""
    venv = tmp_path_factory.mktemp("venv")
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], venv)
    python = venv / "bin" / "python"
    pip = [sys.executable, "-m", "pip", "--python", str(python), "install", "-q"]
    _run([*pip, "--no-deps", "--no-index", str(wheel)], venv)
    site = _run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], venv
    )
    deps = sysconfig.get_paths()["purelib"]  # casadi, python-control, numpy ... of this venv
    (Path(site.stdout.strip()) / "flexctrl_test_dependencies.pth").write_text(deps + "\n")
    return venv


def test_the_wheel_carries_every_kind_of_shipped_file(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    shipped = {
        "flexctrl/data/" + p.relative_to(DATA).as_posix()
        for p in DATA.rglob("*")
        if p.is_file() and p.suffix in (".toml", ".ipynb")
    }
    assert shipped <= names
    for kind, folder in KINDS.items():
        assert any(n.startswith(folder) and n != folder for n in names), kind
    assert "flexctrl/py.typed" in names
    c_sources = ROOT / "src" / "flexctrl" / "control" / "cexport" / "c"
    templates = {f"flexctrl/control/cexport/c/{p.name}" for p in c_sources.iterdir()}
    assert templates and templates <= names  # the C export's sources


def test_the_installed_package_loads_a_shipped_model_by_name(fresh_venv, tmp_path):
    code = (
        "import flexctrl as fc; m = fc.load_model('subedi3link', payload=2.0); "
        "print(fc.__file__); print(m.n_x, m.spec.payload.mass)"
    )
    done = _run([str(fresh_venv / "bin" / "python"), "-c", code], tmp_path)
    where, sizes = done.stdout.strip().splitlines()[-2:]
    assert Path(where).is_relative_to(fresh_venv)  # the wheel's copy, not the checkout's
    n_x, payload = sizes.split()
    assert int(n_x) > 6 and float(payload) == 2.0
    assert list(tmp_path.iterdir()) == []  # nothing written in the working folder


def test_the_installed_command_runs_a_shipped_study_by_name(fresh_venv, tmp_path):
    out = tmp_path / "quickstart"
    _run(
        [
            str(fresh_venv / "bin" / "flexctrl"),
            "study",
            "quickstart",
            "--out",
            str(out),
            "--workers",
            "0",
            "--set",
            "grid.payload=[2.0]",
            "--set",
            "grid.q2=[0]",
            "--set",
            "grid.q3=[0]",
            "--set",
            'grid.controller=["../controllers/pd.toml", "../controllers/lqr.toml"]',
        ],
        tmp_path,
    )
    rows = (out / "results.csv").read_text().splitlines()
    assert len(rows) == 3 and all(",ok," in row for row in rows[1:])
    assert (out / "report.md").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["quickstart"]
