"""``benchmarks/studies_side_by_side.py``: studies side by side, each pass in a fresh process."""

import shutil

import pytest
from studies_side_by_side import bench_studies, format_studies, main


def test_overrides_reach_every_study_and_each_round_has_its_ratio(selftest_study, tmp_path):
    other = selftest_study.with_name("study_selftest_copy.toml")
    shutil.copy(selftest_study, other)
    result = bench_studies(
        [selftest_study, other],
        rounds=2,
        passes=2,
        keep=tmp_path / "bench",
        overrides=["grid.payload=[2.0]", "grid.q3=[0]"],
    )
    assert result["overrides"] == ["grid.payload=[2.0]", "grid.q3=[0]"]
    for per in result["results"].values():
        assert [r["ok"] for r in per["rounds"]] == [
            [4, 4],
            [4, 4],
        ]  # 1 payload x 2 q2 x 1 q3 x 2 controllers
        assert per["tables_identical"]
    ratio = result["ratio_to_first_study"]["study_selftest_copy"]
    walls = [
        [r["wall_s"][0] for r in result["results"][name]["rounds"]]
        for name in ("study_selftest", "study_selftest_copy")
    ]
    assert ratio["first_pass_rounds"] == [b / a for a, b in zip(*walls)]
    assert "(rounds: " in format_studies(result)


def test_a_bad_override_is_refused_before_any_pass(selftest_study, tmp_path, capsys):
    keep = tmp_path / "bench"
    argv = ["--study", str(selftest_study), "--set", "grid.nonsense=[1]", "--keep", str(keep)]
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "nonsense" in err and "passes of study" not in err  # refused before any pass ran
    assert not keep.exists()


def test_a_pass_that_fails_names_its_study_and_the_error(selftest_study, tmp_path):
    from flexctrl.errors import FlexctrlError

    with pytest.raises(FlexctrlError, match=r"study_selftest\.toml.*nonsense"):
        bench_studies(
            [selftest_study],
            rounds=1,
            passes=1,
            keep=tmp_path / "bench",
            overrides=["grid.nonsense=[1]"],
        )
