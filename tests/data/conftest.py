"""Fixtures of the data tests: the real BioTac pilot recordings."""

from pathlib import Path

import pytest

BIOTAC_PILOT_PATH = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "biotac_pilot"


@pytest.fixture(scope="session")
def biotac_pilot_path() -> Path:
    """The pilot's folder of HDF5 files; skips (visibly) where it is absent."""
    if not (BIOTAC_PILOT_PATH / "cork.h5").is_file():
        pytest.skip(f"BioTac pilot data not found at {BIOTAC_PILOT_PATH.resolve()}")
    return BIOTAC_PILOT_PATH
