"""``flexctrl reproduce subedi --reduced``: every numbered table and figure, and the Fig 14
peaks."""

from __future__ import annotations

import importlib.util
import json
import os
import re

import numpy as np
import pytest

from flexctrl.cli import main
from flexctrl.errors import SpecError
from flexctrl.modal.paper_data import SUBEDI_FIG14_PEAKS_HZ
from flexctrl.reproduce.reproduction import reproduce_paper
from flexctrl.reproduce.subedi import NUMBERED
from flexctrl.reproduce.subedi_fft import RESOLUTION_HZ
from flexctrl.sim.fft_peaks import dominant_frequencies


@pytest.fixture(scope="module")
def reduced(tmp_path_factory):
    """The reduced reproduction, run from a folder outside the repository, into ``report/``."""
    elsewhere = tmp_path_factory.mktemp("elsewhere")
    previous = os.getcwd()
    os.chdir(elsewhere)
    try:
        assert main(["reproduce", "subedi", "--out", "report", "--reduced"]) == 0
    finally:
        os.chdir(previous)
    out = elsewhere / "report"
    assert list(elsewhere.iterdir()) == [out]  # nothing else written in the working folder
    return out, json.loads((out / "reproduction.json").read_text())


def test_reproduction_lists_every_numbered_table_and_figure_of_the_paper(reduced):
    out, document = reduced
    names = {re.match(r"(Table|Fig) \d+", item["item"]).group(0) for item in document["items"]}
    assert set(NUMBERED) == {f"Fig {k}" for k in range(1, 15)} | {"Table 1", "Table 2", "Table 3"}
    assert names == set(NUMBERED)
    report = (out / "report.md").read_text()
    order = [report.index(f"## {name}:") for name in NUMBERED]
    assert order == sorted(order)  # the paper's order
    figures = re.findall(r"\]\((figures/[^)]+\.png)\)", report)
    assert len(figures) == 14
    for figure in figures:
        assert (out / figure).stat().st_size > 10_000
    assert document["reduced"] is True
    assert all(
        set(item) == {"item", "paper", "flexctrl", "agrees", "note"} for item in document["items"]
    )


def test_fig14_peaks_agree_with_the_paper_within_the_fft_resolution(reduced):
    _out, document = reduced
    rows = {
        item["item"]: item for item in document["items"] if item["item"].startswith("Fig 14, link")
    }
    assert len(rows) == 6
    for link, printed in enumerate(SUBEDI_FIG14_PEAKS_HZ, start=1):
        for order, paper in zip(("first", "second"), printed):
            row = rows[f"Fig 14, link {link}, {order} peak"]
            ours = float(row["flexctrl"].split()[0])
            assert abs(ours - paper) <= RESOLUTION_HZ, row
            assert row["agrees"]
            if (link, order) != (2, "first"):
                assert abs(ours - paper) < 0.01, row  # the printed digits, on the 2048-point grid


def test_the_paper_fft_grid_is_found_from_a_known_signal():
    """A 2000-sample record padded to 2048 puts a 1.465 Hz sine on bin 3 (1.4648 Hz), not on 1.5
    Hz."""
    t = np.arange(2000) * 1e-3
    signal = np.sin(2 * np.pi * 1.465 * t)
    assert dominant_frequencies(signal, 1e-3, 1, n_fft=2048) == [pytest.approx(3 * RESOLUTION_HZ)]
    assert dominant_frequencies(signal, 1e-3, 1) == [1.5]
    with pytest.raises(ValueError, match="n_fft"):
        dominant_frequencies(signal, 1e-3, 1, n_fft=1000)


def test_unknown_or_missing_paper_is_a_clear_error(tmp_path, capsys):
    with pytest.raises(SpecError, match="allowed: 'subedi', 'pan'"):
        reproduce_paper("smith", tmp_path)
    if importlib.util.find_spec("flexctrl.reproduce.pan") is None:
        assert main(["reproduce", "pan", "--out", str(tmp_path)]) == 2
        assert "not available" in capsys.readouterr().err
