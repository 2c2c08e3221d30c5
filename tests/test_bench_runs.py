"""``flexctrl bench runs``: one study's runs under two source trees, alternated run by run."""

from support import ROOT

from flexctrl import cli
from flexctrl.bench.runs import bench_runs, format_runs

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
        (["--tree", str(root)], "two --tree"),
        (["--tree", str(root), "--tree", str(root / "tests")], "not a flexctrl checkout"),
        (["--tree", str(root), "--tree", str(root), "--exclude", "nmpc"], "KEY=VALUE"),
    ):
        assert cli.main(["bench", "runs", "--study", STUDY, *argv]) != 0
        assert message in capsys.readouterr().err
