"""Shared pytest fixtures."""

from pathlib import Path

import pytest

PHAC2_PATH = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "phac2"


@pytest.fixture(scope="session")
def phac2_path() -> Path:
    """The real PHAC-2 folder; skips (visibly) where it is absent."""
    if not (PHAC2_PATH / "phac2_static_features.npz").is_file():
        pytest.skip(f"PHAC-2 data not found at {PHAC2_PATH.resolve()}")
    return PHAC2_PATH
