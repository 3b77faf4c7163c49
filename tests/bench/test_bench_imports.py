"""Every script of bench/ still imports against today's app/, tests/ harness and siblings.

The service benchmarks take minutes and start real processes, so CI does not run them;
importing each one (as ``python -m bench.NAME`` does, from the repository root) at least
catches a renamed or removed name they use.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_every_bench_script_imports() -> None:
    names = sorted(p.stem for p in (ROOT / "bench").glob("*.py") if p.stem != "__init__")
    assert {"load", "reliability", "bench_framework"} <= set(names)
    code = "import importlib, sys\nfor name in sys.argv[1:]:\n    importlib.import_module(name)\n"
    done = subprocess.run(
        [sys.executable, "-c", code, *(f"bench.{n}" for n in names)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stderr[-4000:]
