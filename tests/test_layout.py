"""The test suite is a regular package, so that its folders never stand in for the
project's packages: ``tests/worker`` is ``tests.worker``, and ``import worker`` in a test
gets the top-level ``worker`` package."""

from pathlib import Path

import worker

ROOT = Path(__file__).resolve().parents[1]


def test_every_test_folder_is_a_package() -> None:
    folders = {p.parent for p in (ROOT / "tests").rglob("*.py") if "__pycache__" not in p.parts}
    missing = sorted(str(f.relative_to(ROOT)) for f in folders if not (f / "__init__.py").is_file())
    assert missing == [], "add an empty __init__.py to each"


def test_tests_import_the_top_level_worker_package() -> None:
    assert __name__ == "tests.test_layout"
    assert worker.__file__ is not None, "a namespace package: a tests folder stood in for it"
    assert Path(worker.__file__).resolve() == ROOT / "worker" / "__init__.py"
