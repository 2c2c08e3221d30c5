"""``flexctrl examples [--copy DIR]``: the shipped files listed by kind, and copied to edit."""

from __future__ import annotations

import json

from support import DATA

from flexctrl.cli import main
from flexctrl.commands.examples import KINDS, examples
from flexctrl.spec.shipped import names
from flexctrl.study.study_file import load_study


def test_every_shipped_file_is_listed_once_under_its_kind(capsys):
    assert main(["examples", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert list(listed) == list(KINDS.values())
    assert {e["name"] for e in listed["models"]} == set(names("model"))
    assert {e["name"] for e in listed["controllers"]} == set(names("controller"))
    assert {e["name"] for e in listed["scenes"]} == set(names("scene"))
    assert {e["name"] for e in listed["notebooks"]} == set(names("notebook"))
    # a file of studies/ is a study or a tuning, never both
    studies = {e["path"] for e in listed["studies"]}
    tunings = {e["path"] for e in listed["tunings"]}
    assert "studies/quickstart.toml" in studies and "studies/tune_lqr.toml" in tunings
    assert "studies/tuning/lqg.toml" in tunings and not studies & tunings
    for entries in listed.values():
        for e in entries:
            assert (DATA / e["path"]).is_file()
            assert e["description"], e["path"]  # every shipped file says what it is


def test_the_listing_names_each_file_with_its_first_comment(capsys):
    assert main(["examples"]) == 0
    out = capsys.readouterr().out
    model = examples()["model"][0]
    assert f"models ({len(examples()['model'])})" in out
    line = next(line for line in out.splitlines() if line.strip().startswith(model.name + " "))
    assert model.description[:40] in line and len(line) <= 100


def test_copy_keeps_the_folders_so_a_copied_study_loads(tmp_path, capsys):
    target = tmp_path / "mine"
    assert main(["examples", "--copy", str(target)]) == 0
    shipped = sorted(p.relative_to(DATA) for p in DATA.rglob("*") if p.is_file())
    copied = sorted(p.relative_to(target) for p in target.rglob("*") if p.is_file())
    assert copied == shipped
    spec = load_study(target / "studies" / "quickstart.toml")
    assert all(str(target) in run.settings["scene"] for run in spec.runs)
    assert str(target) in spec.runs[0].settings["model"]


def test_copy_refuses_to_overwrite_and_copies_nothing(tmp_path, capsys):
    target = tmp_path / "mine"
    (target / "models").mkdir(parents=True)
    (target / "models" / "subedi3link.toml").write_text("# my own arm\n")
    assert main(["examples", "--copy", str(target)]) == 2
    err = capsys.readouterr().err
    assert "subedi3link.toml" in err and "exist already" in err and "--copy" in err
    assert [p.name for p in target.rglob("*") if p.is_file()] == ["subedi3link.toml"]
    assert (target / "models" / "subedi3link.toml").read_text() == "# my own arm\n"
