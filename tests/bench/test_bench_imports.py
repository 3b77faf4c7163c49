"""Every script of bench/ still imports against today's app/ (its test support in
app/testing included) and siblings, and none of them reaches into tests/.

The service benchmarks take minutes and start real processes, so CI does not run them;
importing each one (as ``python -m bench.NAME`` does, from the repository root) at least
catches a renamed or removed name they use.
"""

from __future__ import annotations

import pkgutil
import subprocess
import sys
from pathlib import Path

import app.testing

ROOT = Path(__file__).resolve().parents[2]


def _import_in_a_fresh_interpreter(names: list[str], check: str) -> None:
    code = (
        "import importlib, sys\n"
        "for name in sys.argv[1:]:\n"
        "    importlib.import_module(name)\n" + check
    )
    done = subprocess.run(
        [sys.executable, "-c", code, *names],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stderr[-4000:]


def test_every_bench_script_imports_without_the_tests_folder() -> None:
    names = sorted(p.stem for p in (ROOT / "bench").glob("*.py") if p.stem != "__init__")
    assert {"load", "reliability", "bench_framework"} <= set(names)
    _import_in_a_fresh_interpreter(
        [f"bench.{n}" for n in names],
        "found = sorted(m for m in sys.modules if m == 'tests' or m.startswith('tests.'))\n"
        "assert not found, found\n",
    )


def test_the_test_support_imports_without_pytest() -> None:
    """app.testing ships in the package: it must import where pytest is not installed."""
    names = [f"app.testing.{m.name}" for m in pkgutil.iter_modules(app.testing.__path__)]
    assert {"app.testing.harness", "app.testing.service", "app.testing.scenarios"} <= set(names)
    _import_in_a_fresh_interpreter(
        names,
        "top = {'pytest', '_pytest', 'tests'}\n"
        "found = sorted(m for m in sys.modules if m.split('.')[0] in top)\n"
        "assert not found, found\n",
    )
