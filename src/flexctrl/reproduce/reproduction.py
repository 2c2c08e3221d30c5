"""``reproduce_paper``: run one paper's reproduction and write its two files.

Each paper is a module ``flexctrl.reproduce.<paper>`` with ``run(out_dir, reduced) ->
list[Section]`` (and optionally ``TITLE``); it is imported by name, so a paper whose module
is not installed gives a clear error instead of an import failure.
"""

from __future__ import annotations

import importlib
import importlib.util
import time
from pathlib import Path

from flexctrl.errors import SpecError, keyword_checked
from flexctrl.reproduce.items import write_reproduction

#: The papers, in the order the command lists them.
PAPERS = ("subedi", "pan")


def _paper_module(paper: str):
    if paper not in PAPERS:
        raise SpecError(
            f"value {paper!r} is not allowed; allowed: {', '.join(map(repr, PAPERS))}", key="paper"
        )
    name = f"flexctrl.reproduce.{paper}"
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if exc.name != name:
            raise
        available = [
            p for p in PAPERS if importlib.util.find_spec(f"flexctrl.reproduce.{p}") is not None
        ]
        raise SpecError(
            f"the reproduction of '{paper}' is not available in this version ({name} is missing); "
            f"available: {', '.join(available) or 'none'}",
            key="paper",
        ) from None


@keyword_checked
def reproduce_paper(paper: str, out_dir: str | Path, reduced: bool = False) -> dict:
    """Run the reproduction of one seed paper and write ``report.md`` and ``reproduction.json``.

    Parameters
    ----------
    paper : {"subedi", "pan"}
        Subedi, Tyapin, Hovland (2021) or Pan, Scott, Ulsoy (1990).
    out_dir : str or Path
        Output directory (created); figures go to ``out_dir/figures``.
    reduced : bool
        Fewer steps and cases on the same code paths (the form CI runs).

    Returns
    -------
    dict
        The content of ``reproduction.json``: ``paper`` (the citation), ``reduced``,
        ``seconds`` (wall time) and ``items`` (``item``, ``paper``, ``flexctrl``, ``agrees``,
        ``note``).

    Raises
    ------
    SpecError
        For an unknown paper, or one whose module is not available.
    """
    module = _paper_module(paper)
    out_dir = Path(out_dir)
    start = time.perf_counter()
    sections = module.run(out_dir, reduced)
    seconds = time.perf_counter() - start
    title = getattr(module, "TITLE", paper)
    form = "reduced form (coarser grids, shorter runs, same code paths)" if reduced else "full form"
    preamble = (
        f"`flexctrl reproduce {paper} --out DIR{' --reduced' if reduced else ''}`: {form}, "
        f"{seconds:.0f} s on this machine. Each item sets a number the paper prints, or a "
        "behaviour its text "
        "states, beside flexctrl's, with a verdict and the reason."
    )
    return write_reproduction(
        out_dir,
        title,
        sections,
        preamble,
        extra={"reduced": bool(reduced), "seconds": round(seconds, 1)},
    )
