"""The lint and the layout CI enforces: ``ruff check`` and ``ruff format --check`` over the
whole tree, with the configuration in pyproject.toml (line length 100)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RUFF = Path(sys.executable).parent / "ruff"


@pytest.mark.parametrize("args", [["check", "."], ["format", "--check", "."]])
def test_ruff_finds_nothing(args):
    if not RUFF.exists():
        pytest.fail(f"ruff is not installed beside {sys.executable}: pip install -e '.[test]'")
    run = subprocess.run([str(RUFF), *args], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, (
        f"ruff {' '.join(args)} found problems (fix with ruff check --fix . / ruff format .):\n"
        + run.stdout[-4000:]
        + run.stderr[-2000:]
    )
