"""Turn a dataset spec string into a dataset.

Specs: "simulated", "simulated:N", "phac2[:PATH]", "biotac:DIR" (raw BioTac trials in
HDF5, one file per object) and "folder:DIR" (fixed-shape samples in objects.csv,
samples.npy and samples.csv); docs/DATASETS.md describes the two file formats.
"""

from __future__ import annotations

import os
from pathlib import Path

from app.data.biotac import BioTacDataset, load_biotac
from app.data.dataset import TactileDataset
from app.data.folder import load_folder
from app.data.phac2 import load_phac2
from app.data.simulator import simulate_dataset

ACCEPTED_SPECS = (
    "simulated",
    "simulated:N (N >= 1 objects)",
    "phac2",
    "phac2:PATH",
    "biotac:DIR",
    "folder:DIR",
    "none (serve only: start without classes or attributes)",
)
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


def open_dataset(spec: str, seed: int = 0) -> TactileDataset | BioTacDataset:
    """The dataset a spec names, in the form it is stored in: raw trials (a BioTacDataset)
    for "biotac:DIR", a TactileDataset for the others. Code that fits a featurizer on
    training trials only (an evaluation that splits first) starts here."""
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
    if kind in ("biotac", "folder"):
        if not arg:
            raise _bad(spec, f"'{kind}' needs a folder: '{kind}:DIR'")
        path = Path(arg).expanduser()
        return load_biotac(path) if kind == "biotac" else load_folder(path)
    raise _bad(spec, f"unknown dataset kind {kind!r}")


def load_dataset(spec: str, seed: int = 0) -> TactileDataset:
    """Load the dataset a spec names as samples; ``seed`` only affects simulated data.

    Raw BioTac trials ("biotac:DIR") become tactile images, one per finger, by a
    ``TactileImageFeaturizer`` with its default parameters fitted on all of the dataset's
    trials (right for training on all of them; an evaluation fits on its training trials
    only, from ``open_dataset``).
    """
    data = open_dataset(spec, seed=seed)
    if isinstance(data, BioTacDataset):
        from app.framework.tactile_image import TactileImageFeaturizer, featurize_dataset

        return featurize_dataset(data, TactileImageFeaturizer().fit(data.trials))
    return data
