"""The README's Python example runs as written and prints what it says."""

from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def python_blocks(section: str) -> list[str]:
    text = README.read_text(encoding="utf-8")
    body = text.split(f"## {section}\n", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```python\n(.*?)```", body, flags=re.S)


def test_python_api_example_runs(capsys):
    blocks = python_blocks("Python API")
    assert len(blocks) == 1
    namespace: dict = {}
    exec(compile(blocks[0], "README.md", "exec"), namespace)  # noqa: S102
    out = capsys.readouterr().out
    n = len(namespace["gyro"])
    assert f"({n}, 4)" in out and "final roll" in out and "phase=" in out
    assert namespace["q_many"].shape == (3, n, 4)
    assert namespace["res_6d"].quaternion.shape == (n, 4)
