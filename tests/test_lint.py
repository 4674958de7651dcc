"""The formatter and the linter judge the whole tree ([tool.ruff] in pyproject.toml): a change that is not
formatted, or that the selected rules flag, fails the suite (and so CI) with ruff's own findings."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _ruff() -> list[str]:
    exe = Path(sys.executable).with_name("ruff")
    if exe.exists():
        return [str(exe)]
    found = shutil.which("ruff")
    if found is None:
        pytest.skip("ruff is not installed (it is in the test extra: pip install -e '.[test]')")
    return [found]


@pytest.mark.parametrize("args", [["format", "--check", "."], ["check", "."]], ids=["format", "check"])
def test_ruff_passes_on_the_whole_tree(args):
    res = subprocess.run([*_ruff(), *args], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-2000:]
