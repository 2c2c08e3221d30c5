"""``flexctrl examples [--copy DIR]``: the description files that ship with flexctrl.

Lists the shipped models, controllers, scenes, studies, tunings and notebooks by kind, each
with its name (what the commands accept in place of a path, e.g. ``flexctrl study
quickstart``) and the first line of its first comment.  ``--copy DIR`` copies the whole
shipped tree into ``DIR`` with its folders (``models/``, ``controllers/``, ``studies/``...),
so the files can be edited and their relative references still hold; it refuses to
overwrite a file that exists.
"""

from __future__ import annotations

import argparse
import json
import shutil
import tomllib
from dataclasses import asdict, dataclass
from pathlib import Path

from flexctrl.errors import SpecError
from flexctrl.spec.shipped import data_root

#: The kinds listed, in order, with their headings.
KINDS = {
    "model": "models",
    "controller": "controllers",
    "scene": "scenes",
    "study": "studies",
    "tuning": "tunings",
    "notebook": "notebooks",
}
#: Description width in the listing (characters).
WIDTH = 100


@dataclass(frozen=True)
class Example:
    """One shipped file.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    name : str
        The name the commands accept (the file's stem).
    path : str
        The path inside the shipped tree (``models/subedi3link.toml``), which also works
        as a path from any folder.
    description : str
        The first line of the file's first comment ("" without one).
    """

    kind: str
    name: str
    path: str
    description: str


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``flexctrl examples`` and its options."""
    parser = subparsers.add_parser(
        "examples",
        help="list the shipped models, controllers, scenes, studies, tunings and notebooks, "
        "or copy them into a folder",
        description="Lists the description files that ship with flexctrl by kind, with the "
        "name the commands accept in place of a path and the first line of each file's "
        "comment. --copy DIR copies the whole shipped tree into DIR, folders kept (the "
        "tunings' starting controllers in studies/tuning/start/ too), refusing to overwrite "
        "an existing file.",
    )
    parser.add_argument(
        "--copy", metavar="DIR", help="copy every shipped file into DIR, folders kept"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    return parser


def run(args: argparse.Namespace) -> int:
    """List the shipped files, or copy them; returns the exit status."""
    if args.copy is not None:
        copied = copy_examples(Path(args.copy))
        if args.json:
            print(json.dumps({"copied": [str(p) for p in copied]}, indent=2))
        else:
            print(f"copied {len(copied)} files into {args.copy}")
        return 0
    found = examples()
    if args.json:
        print(json.dumps({KINDS[k]: [asdict(e) for e in v] for k, v in found.items()}, indent=2))
        return 0
    print(format_examples(found))
    return 0


def examples() -> dict[str, list[Example]]:
    """The shipped files of every kind of :data:`KINDS`, sorted by path."""
    root = data_root()
    found: dict[str, list[Example]] = {kind: [] for kind in KINDS}
    for path in sorted(p for p in root.rglob("*") if p.suffix in (".toml", ".ipynb")):
        relative = path.relative_to(root)
        kind = kind_of(relative, path)
        if kind is not None:
            found[kind].append(Example(kind, path.stem, relative.as_posix(), first_comment(path)))
    return found


def kind_of(relative: Path, path: Path) -> str | None:
    """The kind of a shipped file from its folder (and, in ``studies/``, its keys).

    The tunings' starting controllers (``studies/tuning/start/``) are no kind of their own:
    they are copied with the tree but not listed.
    """
    parts = relative.parts
    if parts[0] in ("models", "controllers"):
        return parts[0][:-1]
    if parts[:2] == ("studies", "scenes"):
        return "scene"
    if parts[:2] == ("studies", "notebooks"):
        return "notebook"
    if parts[:2] == ("studies", "tuning"):
        return "tuning" if len(parts) == 3 else None
    if parts[0] == "studies" and len(parts) == 2:
        with open(path, "rb") as fh:
            return "tuning" if "parameters" in tomllib.load(fh) else "study"
    return None


def first_comment(path: Path) -> str:
    """The first line of a TOML file's first comment, or of a notebook's first cell."""
    if path.suffix == ".ipynb":
        cells = json.loads(path.read_text()).get("cells", [])
        source = cells[0].get("source", []) if cells else []
        lines = source.splitlines() if isinstance(source, str) else source
        return lines[0].lstrip("#").strip() if lines else ""
    for line in path.read_text().splitlines():
        if line.startswith("#"):
            return line.lstrip("#").strip()
    return ""


def format_examples(found: dict[str, list[Example]]) -> str:
    """The listing: a heading per kind, then one line per file (name, description)."""
    lines = [
        "Shipped description files: give a name (or the path shown by --json) wherever a "
        "command takes a file; 'flexctrl examples --copy DIR' copies them to edit."
    ]
    for kind, items in found.items():
        lines += ["", f"{KINDS[kind]} ({len(items)})"]
        width = max((len(e.name) for e in items), default=0)
        for e in items:
            text = e.description
            room = WIDTH - width - 4
            if len(text) > room:
                text = text[: room - 3].rstrip() + "..."
            lines.append(f"  {e.name:<{width}}  {text}".rstrip())
    return "\n".join(lines)


def copy_examples(target: Path) -> list[Path]:
    """Copy the whole shipped tree into ``target``, folders kept; the files written.

    Raises
    ------
    SpecError
        If a file to be written exists already (nothing is copied then).
    """
    root = data_root()
    sources = sorted(p for p in root.rglob("*") if p.is_file() and "__pycache__" not in p.parts)
    pairs = [(p, target / p.relative_to(root)) for p in sources]
    existing = [str(dest) for _, dest in pairs if dest.exists()]
    if existing:
        more = f" and {len(existing) - 1} more" if len(existing) > 1 else ""
        raise SpecError(
            f"'{existing[0]}'{more} exist already; allowed: a folder without the shipped "
            "files (nothing was copied)",
            key="--copy",
        )
    for source, dest in pairs:
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(source, dest)
    return [dest for _, dest in pairs]
