"""The package's structure: imports run one way, down the layers of docs/architecture.md.

The graph is built from the source with ``ast`` (no module is imported): every
``import`` and ``from ... import`` (inside functions too) and every string constant
that names a flexctrl module (``"flexctrl.study.executors.closed_loop_executor"``, registry
entries such as ``"flexctrl.scenes.arm_setup:run_arm_scene"``) is an edge; imports under
``if TYPE_CHECKING:`` are not.  A package's ``__init__`` naming its own sub-modules and
a module naming its parent package are not edges (Python imports the parent first
anyway).
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "flexctrl"

#: The layers, bottom to top (docs/architecture.md).  A module may import its own layer's
#: package (the same top-level name) and any layer below; names on one line are peers that
#: must not import each other.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("errors", "user_cache"),
    ("spec",),
    ("beam",),
    ("modal",),
    ("dynamics",),
    ("sim", "linear"),
    ("control",),
    ("loop",),
    ("fidelity",),
    ("scenes",),
    ("analysis", "bench"),
    ("study",),
    ("tuning", "reproduce"),
    ("commands",),
    ("cli",),
)
RANK = {name: rank for rank, names in enumerate(LAYERS) for name in names}
#: The public namespace re-exports from every layer and nothing imports it.
ROOT_MODULE = "flexctrl"
MAX_LINES = 500
MAX_FUNCTION_LINES = 80
MAX_LINE_LENGTH = 100
_MODULE_STRING = re.compile(r"flexctrl(\.\w+)+(:\w+)?")


def _modules() -> dict[str, Path]:
    mods = {}
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE.parent).with_suffix("")
        parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
        mods[".".join(parts)] = path
    return mods


def _resolve(name: str, mods: dict[str, Path]) -> str | None:
    while name and name not in mods:
        name = name.rpartition(".")[0]
    return name or None


def import_graph() -> dict[str, set[str]]:
    """``{module: {modules it imports}}`` for every module of flexctrl (see the module
    docstring)."""
    mods = _modules()
    edges: dict[str, set[str]] = {m: set() for m in mods}
    for module, path in mods.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        is_package = path.name == "__init__.py"
        skipped = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
                skipped.update(id(child) for stmt in node.body for child in ast.walk(stmt))
        for node in ast.walk(tree):
            if id(node) in skipped:
                continue
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = module.split(".") if is_package else module.split(".")[:-1]
                    parts = parts[: len(parts) - (node.level - 1)]
                    base = ".".join(parts + ([base] if base else []))
                targets = [base] + [f"{base}.{alias.name}" for alias in node.names]
            elif (
                isinstance(node, ast.Constant)
                and isinstance(node.value, str)
                and _MODULE_STRING.fullmatch(node.value)
            ):
                targets = [node.value.split(":")[0]]
            for target in targets:
                if not target.startswith("flexctrl"):
                    continue
                resolved = _resolve(target, mods)
                if (
                    resolved is None
                    or resolved == module
                    or (is_package and resolved.startswith(module + "."))
                    or module.startswith(resolved + ".")
                ):
                    continue
                edges[module].add(resolved)
    return edges


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for root in edges:
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            advanced = False
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges[child]))))
                    advanced = True
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            if advanced:
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def _layer(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ROOT_MODULE


def layer_violations(edges: dict[str, set[str]]) -> list[str]:
    """Every import against the layer order, as ``'a -> b (layer x -> layer y)'``."""
    bad = []
    for module, targets in sorted(edges.items()):
        source = _layer(module)
        for target in sorted(targets):
            goal = _layer(target)
            if source == goal:
                continue
            if goal == ROOT_MODULE:
                bad.append(f"{module} -> {target} (nothing inside imports the public namespace)")
            elif source == ROOT_MODULE:
                continue
            elif source not in RANK or goal not in RANK:
                bad.append(f"{module} -> {target} (layer of '{source}' or '{goal}' not in LAYERS)")
            elif RANK[goal] >= RANK[source]:
                bad.append(f"{module} -> {target} (layer '{source}' may not import '{goal}')")
    return bad


def test_every_top_level_name_has_a_layer():
    names = {
        p.stem if p.suffix else p.name
        for p in PACKAGE.iterdir()
        if (p.suffix == ".py" and p.stem != "__init__")
        or (p.is_dir() and (p / "__init__.py").exists())
    }
    assert names - set(RANK) == set()


def test_no_import_cycle():
    assert cycles(import_graph()) == []


def test_imports_run_down_the_layers():
    assert layer_violations(import_graph()) == []


def _sources() -> dict[str, str]:
    return {
        str(p.relative_to(PACKAGE.parent)): p.read_text() for p in sorted(PACKAGE.rglob("*.py"))
    }


def long_modules(sources: dict[str, str]) -> dict[str, int]:
    """Modules over :data:`MAX_LINES` lines, with their length."""
    sizes = {path: len(text.splitlines()) for path, text in sources.items()}
    return {path: n for path, n in sizes.items() if n > MAX_LINES}


def long_functions(sources: dict[str, str]) -> dict[str, int]:
    """Functions and methods over :data:`MAX_FUNCTION_LINES` lines of code.

    From the decorators to the last line, less the docstring: the limit is on the logic a
    reader holds at once, and a numpydoc docstring that documents every parameter is not
    logic.
    """
    found = {}
    for path, text in sources.items():
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
                length = node.end_lineno - first + 1
                doc = node.body[0]
                if (
                    isinstance(doc, ast.Expr)
                    and isinstance(doc.value, ast.Constant)
                    and isinstance(doc.value.value, str)
                ):
                    length -= doc.end_lineno - doc.lineno + 1
                if length > MAX_FUNCTION_LINES:
                    found[f"{path}:{node.lineno} {node.name}"] = length
    return found


def long_lines(sources: dict[str, str]) -> list[str]:
    """Lines over :data:`MAX_LINE_LENGTH` characters, as ``path:line``."""
    return [
        f"{path}:{number}"
        for path, text in sources.items()
        for number, line in enumerate(text.splitlines(), 1)
        if len(line) > MAX_LINE_LENGTH
    ]


def repeated_names(paths: list[str]) -> dict[str, list[str]]:
    """Module file names found in more than one layer (``commands/`` names its sub-commands)."""
    layers: dict[str, set[str]] = {}
    where: dict[str, list[str]] = {}
    for path in paths:
        parts = Path(path).parts
        if parts[-1] == "__init__.py" or parts[1] == "commands" or len(parts) < 3:
            continue
        layers.setdefault(parts[-1], set()).add(parts[1])
        where.setdefault(parts[-1], []).append(path)
    return {name: where[name] for name, found in layers.items() if len(found) > 1}


def test_no_module_over_the_line_limit():
    assert long_modules(_sources()) == {}


def test_no_function_over_the_line_limit():
    assert long_functions(_sources()) == {}


def test_no_line_over_the_length_limit():
    assert long_lines(_sources()) == []


def test_no_module_name_repeats_across_layers():
    assert repeated_names(list(_sources())) == {}


def test_the_package_imports_nothing_from_the_lab():
    """``benchmarks/`` and ``tools/`` measure the package; the package never imports them."""
    lab = {"benchmarks", "tools", "tests", "docs"}
    bad = []
    for path, text in _sources().items():
        for node in ast.walk(ast.parse(text)):
            names = []
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and not node.level:
                names = [node.module or ""]
            bad += [f"{path}: {name}" for name in names if name.split(".")[0] in lab]
    assert bad == []


def test_the_size_checks_can_fail():
    """A long module, function and line and a repeated name planted in copies are found."""
    body = '    """A docstring is not counted."""\n' + "    x = 1\n" * (MAX_FUNCTION_LINES + 1)
    planted = {
        "flexctrl/sim/a.py": "x = 1\n" * (MAX_LINES + 1),
        "flexctrl/sim/b.py": f"def f():\n{body}",
        "flexctrl/sim/c.py": "y = '" + "z" * MAX_LINE_LENGTH + "'\n",
    }
    assert list(long_modules(planted)) == ["flexctrl/sim/a.py"]
    assert list(long_functions(planted)) == ["flexctrl/sim/b.py:1 f"]
    assert long_lines(planted) == ["flexctrl/sim/c.py:1"]
    paths = ["flexctrl/sim/same.py", "flexctrl/loop/same.py", "flexctrl/commands/study.py"]
    assert list(repeated_names(paths)) == ["same.py"]


def test_the_checks_can_fail():
    """A cycle and an upward import planted in a copy of the graph are found."""
    edges = import_graph()
    edges["flexctrl.errors"] = edges["flexctrl.errors"] | {"flexctrl.spec.arm"}
    assert any("flexctrl.errors" in c for c in cycles(edges))
    assert (
        "flexctrl.errors -> flexctrl.spec.arm (layer 'errors' may not import 'spec')"
        in layer_violations(edges)
    )


@pytest.mark.parametrize(
    "code, heavy",
    [
        ("import flexctrl", ("casadi", "control", "osqp", "matplotlib")),
        (
            "import flexctrl.spec, flexctrl.spec.controller_reader, "
            "flexctrl.spec.controller_settings, flexctrl.spec.scene, "
            "flexctrl.spec.closed_loop_scene, "
            "flexctrl.spec.fem_scene, flexctrl.spec.reference; "
            "flexctrl.spec.scene.load_scene('studies/scenes/move_joint1_30deg.toml'); "
            "flexctrl.spec.controller_reader.load_controller('controllers/lqr.toml')",
            ("casadi", "control", "osqp"),
        ),
    ],
)
def test_light_imports_stay_light(code, heavy):
    """``import flexctrl`` and reading descriptions load neither casadi nor python-control."""
    probe = f"{code}; import sys; print(','.join(m for m in {heavy!r} if m in sys.modules))"
    out = subprocess.run(
        [sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == ""
