"""The package under test is the installed wheel, not the source tree.

``scripts/test`` installs the wheel ``scripts/wheel`` built and sets ``A2PERF_EXPECT_WHEEL`` to
its file name; elsewhere (a development install) these checks skip.
"""

from __future__ import annotations

import importlib.metadata
import json
import os
from pathlib import Path

import pytest

import a2perf_rs

SOURCE = Path(__file__).resolve().parents[1] / "a2perf_rs"
EXPECTED = os.environ.get("A2PERF_EXPECT_WHEEL")


@pytest.mark.skipif(EXPECTED is None, reason="A2PERF_EXPECT_WHEEL is not set (not scripts/test)")
def test_the_imported_package_is_the_installed_abi3_manylinux_wheel() -> None:
    assert EXPECTED is not None
    package = Path(a2perf_rs.__file__).resolve().parent
    assert package != SOURCE, f"a2perf_rs was imported from the source tree {package}"
    dist = importlib.metadata.distribution("a2perf-rs")
    assert Path(dist.locate_file("a2perf_rs")).resolve() == package
    # pip records where the distribution came from: the wheel file itself, not a directory build.
    direct_url = json.loads(dist.read_text("direct_url.json") or "{}")
    assert "archive_info" in direct_url, direct_url
    assert direct_url["url"].endswith("/" + EXPECTED), direct_url
    tags = [
        line.split(":", 1)[1].strip()
        for line in (dist.read_text("WHEEL") or "").splitlines()
        if line.startswith("Tag:")
    ]
    assert tags and all("-abi3-" in t and "manylinux" in t for t in tags), tags
    # The native module is the stable-ABI build, one for every CPython >= 3.9.
    native = Path(a2perf_rs._native.__file__).name
    assert native.endswith(".abi3.so"), native
