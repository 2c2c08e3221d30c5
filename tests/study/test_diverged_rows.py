"""A study in which a run diverges: its row is marked, its residual cells are empty with the
reason, the report lists it apart, and rankings never mix it with finished runs.

The LQR designed at 2 kg and q = (30, 0, 0) deg is run at q2 = 90 deg with 0 kg (linearly
unstable there: it leaves the tight deflection bound within 0.2 s) and with 2 kg (stable).
"""

from __future__ import annotations

import re

from support import ROOT

from flexctrl import cli
from flexctrl.study.store import ResultStore

STUDY = """
name = "diverging"
executor = "closed_loop"
seed = 1
scene = "{root}/studies/scenes/move_joint1_30deg.toml"
model = "{root}/models/subedi3link.toml"
configuration = [0, 0, 0]
metrics = ["tip_residual_rms", "stable", "divergence_time"]

[set]
"scene.design_configuration" = [30.0, 0.0, 0.0]
"scene.design_payload" = 2.0
"scene.duration" = 5.0
"scene.metrics.divergence_deflection" = 0.01

[grid]
payload = [0.0, 2.0]
q2 = [90]
controller = ["{tests}/data/controllers/lqr_full_state.toml"]

[trajectories]
decimation = 20

[report]
metric = "tip_residual_rms"
rank_by = "payload"
group_by = "controller"
"""


def _ranking(report: str) -> list[list[str]]:
    """The cells of the report's ranking table rows (rank, payload, median ...), in order."""
    section = report.split("## Ranking", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if re.match(r"^\| \d+ \|", line)]
    return [[cell.strip() for cell in row.strip("|").split("|")] for row in rows]


def test_a_diverged_run_is_marked_listed_apart_and_ranked_by_direction(tmp_path, root):
    study = tmp_path / "diverging.toml"
    study.write_text(STUDY.format(root=root.as_posix(), tests=(ROOT / "tests").as_posix()))
    out = tmp_path / "out"
    assert cli.main(["study", str(study), "--out", str(out), "--workers", "0", "--quiet"]) == 0
    rows = {r["payload"]: r for r in ResultStore(out).read_table().rows}
    gone, held = rows[0.0], rows[2.0]
    assert gone["status"] == held["status"] == "ok"
    assert gone["stable"] == 0 and 0 < gone["divergence_time"] < 1.0
    assert gone["tip_residual_rms"] is None  # an empty cell, not a number
    assert "no tip_residual_rms" in gone["error"] and "diverged at" in gone["error"]
    assert held["stable"] == 1 and held["divergence_time"] is None
    assert held["tip_residual_rms"] > 0

    report = (out / "report.md").read_text()
    assert "1 of them diverged" in report
    diverged = report.split("## Diverged runs", 1)[1]
    assert gone["run_id"] in diverged and held["run_id"] not in diverged
    # the residual ranking holds the finished run only
    # payload, median, runs ranked, diverged runs
    ranked = [(c[1], c[2], c[5], c[6]) for c in _ranking(report)]
    assert ranked == [("2", ranked[0][1], "1", "0"), ("0", "-", "0", "1")]

    # ranking by stable: higher is better, so the stable run comes first
    assert cli.main(["report", str(out), "--metric", "stable"]) == 0
    report = (out / "report.md").read_text()
    assert "(higher is better)" in report and "best first (highest)" in report
    assert [(c[1], c[2]) for c in _ranking(report)] == [("2", "1"), ("0", "0")]
    # both runs are worst-case candidates, but they share a cell (the figure draws every
    # payload of it): one figure, not the same one twice
    assert report.count("](figures/worst_") == 1
