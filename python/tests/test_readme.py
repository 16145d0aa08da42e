"""The Python examples of the README and of the guides in docs/ run exactly as written.

Every ```python block runs; a ```py block is a sketch with placeholders (``...``) and is not run.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from conftest import REPO

PAGES = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]


def python_blocks(path: Path) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", path.read_text(), flags=re.S | re.M)


RUNNABLE = [p for p in PAGES if python_blocks(p)]


def test_the_front_page_and_the_python_guide_have_examples() -> None:
    names = {p.relative_to(REPO).as_posix() for p in RUNNABLE}
    assert {"README.md", "docs/python.md"} <= names, names


@pytest.mark.parametrize("page", RUNNABLE, ids=lambda p: p.relative_to(REPO).as_posix())
def test_python_examples_run(page: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for code in python_blocks(page):
        exec(compile(code, str(page.relative_to(REPO)), "exec"), {"__name__": "docs_example"})
    out = capsys.readouterr().out
    expected = {"README.md": "return IQM ", "docs/python.md": "proxy cost "}
    want = expected.get(page.relative_to(REPO).as_posix())
    if want is not None:
        assert want in out, out
