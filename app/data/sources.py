"""Turn a dataset spec string ("simulated", "simulated:N", "phac2[:PATH]") into a dataset."""

from __future__ import annotations

import os
from pathlib import Path

from app.data.dataset import TactileDataset
from app.data.phac2 import load_phac2
from app.data.simulator import simulate_dataset

ACCEPTED_SPECS = ("simulated", "simulated:N (N >= 1 objects)", "phac2", "phac2:PATH")
PHAC2_ENV = "TACTILE_PHAC2_PATH"
_REPO_ROOT = Path(__file__).resolve().parents[2]


class DatasetSpecError(ValueError):
    """A dataset spec string that is not one of the accepted forms."""


def _bad(spec: str, why: str) -> DatasetSpecError:
    return DatasetSpecError(
        f"bad dataset spec {spec!r}: {why}; accepted forms: {', '.join(ACCEPTED_SPECS)}"
    )


def default_phac2_path() -> Path:
    """First existing of $TACTILE_PHAC2_PATH, <repo>/../shared/data/phac2, ./../shared/data/phac2.

    When none exists, the first candidate is returned so the loader's error names it.
    """
    candidates = [
        _REPO_ROOT / ".." / "shared" / "data" / "phac2",
        Path("..", "shared", "data", "phac2"),
    ]
    if os.environ.get(PHAC2_ENV):
        candidates.insert(0, Path(os.environ[PHAC2_ENV]))
    return next((c for c in candidates if c.is_dir()), candidates[0])


def load_dataset(spec: str, seed: int = 0) -> TactileDataset:
    """Load the dataset a spec names; ``seed`` only affects simulated data."""
    kind, sep, arg = spec.strip().partition(":")
    if kind == "simulated":
        if not sep:
            return simulate_dataset(seed=seed)
        if not (arg.isascii() and arg.isdigit()) or int(arg) < 1:
            raise _bad(spec, "the object count must be a positive integer")
        return simulate_dataset(n_objects=int(arg), seed=seed)
    if kind == "phac2":
        if sep and not arg:
            raise _bad(spec, "the path after 'phac2:' is empty")
        return load_phac2(Path(arg).expanduser() if sep else default_phac2_path())
    raise _bad(spec, f"unknown dataset kind {kind!r}")
