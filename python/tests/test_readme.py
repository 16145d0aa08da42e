"""The README's Python example runs exactly as written."""

from __future__ import annotations

import re

from conftest import REPO


def test_readme_python_example_runs(capsys) -> None:
    text = (REPO / "README.md").read_text()
    section = text.split("## Python\n", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    assert blocks, "the README's Python section has no example"
    for code in blocks:
        exec(compile(code, "README.md", "exec"), {"__name__": "readme"})
    out = capsys.readouterr().out
    assert "return " in out and "proxy cost " in out
