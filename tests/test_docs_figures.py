"""The figures of README.md and docs/: each one shown somewhere, each one there, small, and made by
`make figures`."""

from __future__ import annotations

import re
from pathlib import Path

from support import ROOT

FIGURES = ROOT / "docs" / "figures"
#: A Markdown image or a MyST figure directive.
IMAGE = re.compile(r"!\[[^\]]*\]\(([^)]+\.png)\)|```\{figure\} (\S+\.png)")


def _references() -> dict[Path, list[str]]:
    """Resolved image path -> the documents that show it."""
    shown: dict[Path, list[str]] = {}
    pages = [p for p in sorted((ROOT / "docs").rglob("*.md")) if "_build" not in p.parts]
    for doc in [ROOT / "README.md", *pages]:
        for image, figure in IMAGE.findall(doc.read_text()):
            target = image or figure
            shown.setdefault((doc.parent / target).resolve(), []).append(doc.name)
    return shown


def test_every_figure_is_shown_and_every_shown_figure_exists():
    shown = _references()
    pngs = sorted(FIGURES.glob("*.png"))
    assert len(pngs) >= 5
    assert [p.name for p in pngs if p.resolve() not in shown] == []
    missing = [
        f"{p.relative_to(ROOT)} (in {', '.join(docs)})"
        for p, docs in shown.items()
        if ROOT / "docs" in p.parents and not p.is_file()
    ]
    assert missing == []


def test_figures_are_small_and_made_by_make_figures():
    script = (ROOT / "tools" / "make_figures.py").read_text()
    assert "tools/make_figures.py" in (ROOT / "Makefile").read_text()
    for png in FIGURES.glob("*.png"):
        assert png.stat().st_size < 200 * 1024, f"{png.name}: {png.stat().st_size / 1024:.0f} KiB"
        assert f'"{png.name}"' in script, f"{png.name} is not drawn by tools/make_figures.py"
