"""The README's Python API example runs as written (so it cannot rot)."""

from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def _python_api_block() -> str:
    text = README.read_text(encoding="utf-8")
    section = text.split("\n## Python API\n", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    assert len(blocks) == 1, "the Python API section holds one python block"
    return blocks[0]


def test_python_api_example_runs(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code = _python_api_block()
    exec(compile(code, str(README) + ":Python API", "exec"), {"__name__": "readme_example"})
    out = capsys.readouterr().out
    assert re.search(r"source estimate \([\d.]+, [\d.]+\) m, [\d.]+ m off; normalized entropy [\d.]+", out)
    assert re.search(r"next: measure at cell \(\d+, \d+\); stop now\? (True|False)", out)
    assert (tmp_path / "case.npz").is_file()
