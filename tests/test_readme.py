"""The README's Python example runs as written (from the repository root)."""

from __future__ import annotations

import os
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_readme_python_example_runs(tmp_path, monkeypatch):
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert blocks, "README has no python example"
    monkeypatch.chdir(ROOT)
    code = blocks[0].replace('"out/api_example"', repr(str(tmp_path / "api_example")))
    namespace: dict = {}
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the example must be clean (e.g. holding torque within the limits)
        exec(compile(code, "README.md", "exec"), namespace)  # noqa: S102 - our own README
    metrics = namespace["run"].summary["metrics"]
    assert metrics["tip_residual_rms"] > 0 and (tmp_path / "api_example" / "summary.json").is_file()


def test_readme_opens_with_the_two_commands():
    lines = [l for l in (ROOT / "README.md").read_text().splitlines() if l.strip()]
    assert lines[1] == "```sh" and lines[2].startswith("make demo") and lines[3].startswith("make test")
    assert "make test" in (ROOT / ".ci" / "run").read_text()
