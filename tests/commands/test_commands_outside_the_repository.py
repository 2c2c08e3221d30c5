"""The shipped files are found by name from any folder: the commands a user types first.

Each command runs as a user runs it, in a fresh process whose working folder is outside the
repository; it may write its ``--out`` folder there and nothing else.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from support import ROOT


def flexctrl(folder: Path, *argv: str) -> subprocess.CompletedProcess:
    """``flexctrl ARGV`` run in ``folder`` (outside the repository)."""
    assert ROOT not in folder.resolve().parents
    return subprocess.run(
        [sys.executable, "-m", "flexctrl.cli", *argv],
        cwd=folder,
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_a_shipped_study_runs_by_name(tmp_path):
    done = flexctrl(
        tmp_path,
        "study",
        "quickstart",
        "--out",
        "quick",
        "--workers",
        "0",
        "--set",
        "grid.payload=[2.0]",
        "--set",
        "grid.q2=[0]",
        "--set",
        "grid.q3=[0]",
        "--set",
        'grid.controller=["../controllers/lqr.toml"]',
    )
    assert done.returncode == 0, done.stderr
    assert "1 ok, 0 failed" in done.stderr
    assert (tmp_path / "quick" / "results.csv").read_text().count("\n") == 2  # header + 1 run
    assert sorted(p.name for p in tmp_path.iterdir()) == ["quick"]


def test_a_shipped_scene_simulates_by_name(tmp_path):
    done = flexctrl(tmp_path, "simulate", "move_joint1_30deg", "--out", "move", "--no-plots")
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "move" / "summary.json").read_text())
    assert summary["t_final"] > 1.0 and summary["metrics"]["tip_residual_rms"] < 1e-3  # m
    assert "move_joint1_30deg with lqr" in done.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["move"]


def test_a_missing_name_lists_the_shipped_ones(tmp_path):
    done = flexctrl(tmp_path, "study", "quickstrat", "--out", "x")
    assert done.returncode == 2
    assert "quickstart" in done.stderr and not (tmp_path / "x").exists()
