"""Shared service fixtures live in tests/service_fixtures.py."""

import sys
from pathlib import Path

# The project root must be on sys.path: otherwise the folder tests/worker, as a
# namespace package, would shadow the real top-level ``worker`` package.
_ROOT = str(Path(__file__).resolve().parents[2])
if _ROOT not in sys.path:
    sys.path.insert(0, _ROOT)

from tests.service_fixtures import *  # noqa: E402, F403
