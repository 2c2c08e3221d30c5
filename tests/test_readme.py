"""The README's Python example runs as written (from the repository root) and says what it
claims."""

from __future__ import annotations

import re

from support import ROOT


def test_readme_python_example_runs(tmp_path, monkeypatch):
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert blocks, "README has no python example"
    monkeypatch.chdir(ROOT)
    code = blocks[0].replace("out/api_example", str(tmp_path))
    assert code != blocks[0], "the example writes outside out/api_example"
    namespace: dict = {}
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter(
            "error"
        )  # the example must be clean (e.g. holding torque within the limits)
        exec(compile(code, "README.md", "exec"), namespace)  # noqa: S102 - our own README
    results = namespace["results"]
    rms = {name: res.metrics["tip_residual_rms"] for name, res in results.items()}
    # what the text under the block states, to the printed digits
    for name, printed in re.findall(
        r"(PD|LQR|MPC) (\d+\.\d\d) mm", text.split("```python", 1)[1].split("## ", 1)[0]
    ):
        assert f"{1e3 * rms[name]:.2f}" == printed, (name, rms[name], printed)
    assert rms["LQR"] < rms["PD"]
    assert (
        namespace["off"].metrics["stable"] == 0
    )  # the MPC the block designed, run on another plant
    assert namespace["off"].controller is results["MPC"].controller
    assert (tmp_path / "compare.png").stat().st_size > 10_000
    assert (tmp_path / "summary.json").is_file()


def test_readme_is_a_front_page():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 200
    code = re.findall(r"```python\n(.*?)```", text, flags=re.S)[0]
    assert 15 <= len(code.strip().splitlines()) <= 25
    for word in ("round", "issue", "stop", "earlier", "latest"):
        assert not re.search(rf"\b{word}s?\b", text, flags=re.I), word


def test_readme_opens_with_the_two_commands():
    lines = [l for l in (ROOT / "README.md").read_text().splitlines() if l.strip()]
    assert (
        lines[1] == "```sh"
        and lines[2].startswith("make demo")
        and lines[3].startswith("make test")
    )
    assert "make test" in (ROOT / ".ci" / "run").read_text()
