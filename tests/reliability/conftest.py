"""Shared service fixtures live in tests/service_fixtures.py."""

import sys
from pathlib import Path

_ROOT = str(Path(__file__).resolve().parents[2])
if _ROOT not in sys.path:
    sys.path.insert(0, _ROOT)

from tests.service_fixtures import *  # noqa: E402, F403
