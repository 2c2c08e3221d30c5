"""The README's reproduction summary and the documentation's full table are the ones generated
from docs/reproduction/*.json."""

from __future__ import annotations

import json

from support import ROOT

from flexctrl.reproduce.readme import BEGIN, END, SUMMARY_BEGIN, rewrite, summary, table


def test_readme_and_docs_tables_are_generated_from_the_stored_full_runs():
    sources = sorted((ROOT / "docs" / "reproduction").glob("*.json"))
    assert sources, "docs/reproduction/ holds the full runs' reproduction.json"
    readme, full = ROOT / "README.md", ROOT / "docs" / "reproduction" / "table.md"
    assert SUMMARY_BEGIN in readme.read_text() and BEGIN in full.read_text()
    for page in (readme, full):
        assert rewrite(page, sources) == page.read_text(), (
            f"run: python -m flexctrl.reproduce.readme {page.relative_to(ROOT)} "
            "docs/reproduction/*.json"
        )
    for source in sources:
        assert json.loads(source.read_text())["reduced"] is False


def test_table_counts_and_lists_what_differs():
    doc = {
        "paper": 'Smith, Jones (1999), "A paper", J 1',
        "items": [
            {"item": "Table 1, a", "paper": "1", "flexctrl": "1", "agrees": True, "note": ""},
            {"item": "Table 1, b", "paper": "2", "flexctrl": "3 | 4", "agrees": False, "note": ""},
            {"item": "Fig 2, c", "paper": "x", "flexctrl": "x", "agrees": True, "note": ""},
        ],
    }
    rows = table([doc]).splitlines()
    assert rows[2] == "| Smith et al. (1999) | Table 1 | 1 of 2 | Table 1, b: 3 / 4 |"
    assert rows[3] == "| Smith et al. (1999) | Fig 2 | 1 of 1 |  |"
    assert BEGIN.startswith("<!--") and END.startswith("<!--")
    assert summary([doc]).splitlines()[2] == "| Smith et al. (1999) | 2 of 3 | Table 1 |"
