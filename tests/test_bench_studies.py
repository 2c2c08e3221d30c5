"""``flexctrl bench studies``: study files side by side, each pass in a fresh process, with shared overrides."""


import shutil

from flexctrl import cli
from flexctrl.bench.studies import bench_studies, format_studies


def test_overrides_reach_every_study_and_each_round_has_its_ratio(selftest_study, tmp_path):
    other = selftest_study.with_name("study_selftest_copy.toml")
    shutil.copy(selftest_study, other)
    result = bench_studies([selftest_study, other], rounds=2, passes=2, keep=tmp_path / "bench",
                           overrides=["grid.payload=[2.0]", "grid.q3=[0]"])
    assert result["overrides"] == ["grid.payload=[2.0]", "grid.q3=[0]"]
    for per in result["results"].values():
        assert [r["ok"] for r in per["rounds"]] == [[4, 4], [4, 4]]  # 1 payload x 2 q2 x 1 q3 x 2 controllers
        assert per["tables_identical"]
    ratio = result["ratio_to_first_study"]["study_selftest_copy"]
    walls = [[r["wall_s"][0] for r in result["results"][name]["rounds"]] for name in ("study_selftest", "study_selftest_copy")]
    assert ratio["first_pass_rounds"] == [b / a for a, b in zip(*walls)]
    assert "(rounds: " in format_studies(result)


def test_a_bad_override_is_refused_before_any_pass(selftest_study, tmp_path, capsys):
    keep = tmp_path / "bench"
    assert cli.main(["bench", "studies", "--study", str(selftest_study), "--set", "grid.nonsense=[1]", "--keep", str(keep)]) != 0
    assert "nonsense" in capsys.readouterr().err
    assert not keep.exists()
