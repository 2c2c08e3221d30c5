"""How the command line ends when the user does something ordinary: radians in ``--q``, Ctrl-C
during a report, a pipe into ``head``."""

from __future__ import annotations

import subprocess
import sys

import pytest
from support import MODEL

from flexctrl import cli

FLEXCTRL = [sys.executable, "-m", "flexctrl.cli"]


@pytest.mark.parametrize("command", ["modes", "linearize"])
def test_radians_in_q_warn_on_stderr_as_in_files(command):
    done = subprocess.run(
        [*FLEXCTRL, command, str(MODEL), "--q", "0.785", "0.3", "0.1", "--fidelity", "amm:1"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert (
        f"flexctrl {command}: warning: key '--q': value [0.785, 0.3, 0.1] looks like radians"
        in (done.stderr)
    )
    quiet = subprocess.run(
        [*FLEXCTRL, command, str(MODEL), "--q", "45", "17", "5.5", "--fidelity", "amm:1"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "looks like radians" not in quiet.stderr


def test_a_closed_pipe_ends_quietly():
    """``flexctrl modes ... | head -0``: the reader leaves before the output is written."""
    proc = subprocess.Popen(
        [*FLEXCTRL, "modes", str(MODEL), "--q", "30", "0", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait() == 141
    assert "Traceback" not in err and "BrokenPipeError" not in err


def test_ctrl_c_during_a_report_stops_with_one_line_and_a_hint(tmp_path, monkeypatch, capsys):
    import flexctrl.study.report as report

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(report, "write_report", interrupted)
    assert cli.main(["report", str(tmp_path)]) == 130
    err = capsys.readouterr().err
    assert err == (
        f"flexctrl report: interrupted; report.md is unchanged; 'flexctrl report {tmp_path}' "
        "draws it again\n"
    )


def test_check_counts_one_link_in_the_singular(capsys):
    from support import ROOT

    assert cli.main(["check", str(ROOT / "tests" / "data" / "models" / "one_link.toml")]) == 0
    assert "(model 'one_link', 1 link)" in capsys.readouterr().out
