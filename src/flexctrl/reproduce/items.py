"""The plain records a reproduction is made of, and the writer of its two files.

An :class:`Item` is one number or one described behaviour of a paper set beside the
toolkit's, named after the paper's own numbering ("Table 3, link 1, mode 1, 0 kg",
"Fig 14, link 2, first peak"). A :class:`Section` is one table or figure of the paper: its
items, the figures drawn for it and the text that explains the verdicts (decisions where
the paper is ambiguous, reasons where it differs).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class Item:
    """One printed value (or described behaviour) of a paper beside the toolkit's.

    Attributes
    ----------
    item : str
        Named after the paper's numbering, e.g. ``"Table 3, link 1, mode 1, 0 kg"``.
    paper : str
        What the paper prints (a number with its unit, or the behaviour in words).
    flexctrl : str
        What the toolkit gives, in the same unit.
    agrees : bool
        The verdict.
    note : str
        Why it agrees or differs (tolerance used, decision taken, cause found).
    """

    item: str
    paper: str
    flexctrl: str
    agrees: bool
    note: str = ""

    def __post_init__(self) -> None:
        # verdicts computed with numpy arrive as numpy.bool_, which JSON does not take
        object.__setattr__(self, "agrees", bool(self.agrees))


@dataclass
class Section:
    """One table or figure of a paper, in the paper's order.

    Attributes
    ----------
    title : str
        The paper's name for it, e.g. ``"Table 3: clamped-mass frequencies"``.
    text : str
        Markdown shown under the title (what was run, decisions, explanations).
    items : list of Item
    figures : list of str
        PNG paths relative to the output directory, shown after the text.
    """

    title: str
    text: str = ""
    items: list[Item] = field(default_factory=list)
    figures: list[str] = field(default_factory=list)


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _table(items: list[Item]) -> list[str]:
    lines = ["| item | paper | flexctrl | verdict | note |", "|---|---|---|---|---|"]
    for it in items:
        verdict = "agrees" if it.agrees else "differs"
        lines.append(
            f"| {_cell(it.item)} | {_cell(it.paper)} | {_cell(it.flexctrl)} | {verdict} | "
            f"{_cell(it.note)} |"
        )
    return lines


def write_reproduction(
    out_dir: Path,
    title: str,
    sections: list[Section],
    preamble: str = "",
    extra: dict | None = None,
) -> dict:
    """Write ``out_dir/report.md`` and ``out_dir/reproduction.json``; return the JSON document.

    Parameters
    ----------
    out_dir : Path
        Output directory (created).
    title : str
        The paper's citation, used as the report's heading.
    sections : list of Section
        In the paper's order.
    preamble : str
        Markdown after the heading (what was run, how long it took, reduced or full).
    extra : dict, optional
        More top-level keys of ``reproduction.json`` (e.g. ``reduced``, ``seconds``).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    items = [it for s in sections for it in s.items]
    agree = sum(it.agrees for it in items)
    lines = [f"# Reproduction: {title}", ""]
    if preamble:
        lines += [preamble, ""]
    lines += [f"{agree} of {len(items)} items agree.", ""]
    for s in sections:
        lines += [f"## {s.title}", ""]
        if s.text:
            lines += [s.text, ""]
        if s.items:
            lines += _table(s.items) + [""]
        lines += [f"![{s.title}]({fig})" for fig in s.figures]
        if s.figures:
            lines.append("")
    (out_dir / "report.md").write_text("\n".join(lines))
    document = {"paper": title, **(extra or {}), "items": [asdict(it) for it in items]}
    (out_dir / "reproduction.json").write_text(json.dumps(document, indent=1) + "\n")
    return document
