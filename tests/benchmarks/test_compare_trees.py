"""``benchmarks/compare_trees.py``: one study's runs under two source trees, alternated."""

import pytest
from compare_trees import bench_runs, format_runs, import_root, main
from support import ROOT

STUDY = "tests/data/study_selftest.toml"


def test_the_same_tree_twice_gives_the_same_metrics_and_every_run():
    root = ROOT
    result = bench_runs(root / STUDY, [root, root], exclude=["controller=stiff", "payload=0.0"])
    assert result["runs"] == 6  # 24 runs, half of them stiff, half of the rest at 0 kg
    assert result["max_metric_relative_difference"] == 0.0 and result["where"] is None
    assert list(result["summed_run_wall_s"][0]) == ["soft"]
    assert all(t > 0 for t in result["total_s"])
    assert "soft" in format_runs(result)


def test_bad_arguments_are_refused(capsys):
    root = ROOT
    for argv, message in (
        (["--tree", str(root)], "exactly two --tree"),
        (["--tree", str(root), "--tree", str(root / "tests")], "not a flexctrl checkout"),
        (["--tree", str(root), "--tree", str(root), "--exclude", "nmpc"], "KEY=VALUE"),
    ):
        with pytest.raises(SystemExit) as exit_info:
            main(["--study", STUDY, *argv])
        assert exit_info.value.code == 2
        assert message in capsys.readouterr().err


def test_both_layouts_are_found(tmp_path):
    """A tree of the src layout and one with the package at its top both give their import root."""
    assert import_root(ROOT) == ROOT / "src"
    old = tmp_path / "old"
    (old / "flexctrl").mkdir(parents=True)
    (old / "flexctrl" / "__init__.py").write_text("")
    assert import_root(old) == old
