"""Loader for the PHAC-2 static tactile features (real PR2/BioTac data, see data README)."""

from __future__ import annotations

import csv
import zipfile
from pathlib import Path

import numpy as np

from app.data.dataset import DatasetError, TactileDataset

FEATURES_FILE = "phac2_static_features.npz"
OBJECTS_FILE = "objects.csv"
_KEYS = ("features", "object_id", "trial", "phases", "feature_names")


class Phac2FormatError(DatasetError):
    """The PHAC-2 files exist but do not have the documented layout."""


def _require(path: Path) -> Path:
    if not path.exists():
        raise FileNotFoundError(f"PHAC-2 data not found: {path}")
    return path


def _read_npz(path: Path) -> dict[str, np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as npz:
            missing = [k for k in _KEYS if k not in npz.files]
            if missing:
                raise Phac2FormatError(f"{path} lacks keys {missing}; expected {list(_KEYS)}")
            return {k: npz[k] for k in _KEYS}
    except Phac2FormatError:
        raise
    # np.load raises any of these for truncated/garbled archives.
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise Phac2FormatError(f"cannot read {path}: {exc}") from exc


def _read_objects(path: Path) -> tuple[list[int], list[str], list[str], np.ndarray]:
    """Object ids, names, adjective names and the (K, 24) 0/1 matrix, sorted by id."""
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    if len(rows) < 2 or rows[0][:2] != ["object_id", "name"] or len(rows[0]) < 3:
        raise Phac2FormatError(f"{path} must start with columns object_id,name,<adjectives>")
    header, body = rows[0], rows[1:]
    try:
        ids = [int(r[0]) for r in body]
        matrix = np.array([[int(x) for x in r[2:]] for r in body], dtype=np.int64)
    except (ValueError, IndexError) as exc:
        raise Phac2FormatError(f"{path} has a malformed row: {exc}") from exc
    if matrix.shape != (len(body), len(header) - 2) or not np.isin(matrix, (0, 1)).all():
        raise Phac2FormatError(f"{path}: adjective columns must all be 0/1 in every row")
    if len(set(ids)) != len(ids):
        raise Phac2FormatError(f"{path} repeats an object_id")
    order = np.argsort(ids, kind="stable")
    return ([ids[i] for i in order], [body[i][1] for i in order], header[2:], matrix[order])


def load_phac2(path: str | Path, min_objects_per_attribute: int = 3) -> TactileDataset:
    """PHAC-2 as a flat (600, 188) dataset; attributes present in >= the given number of objects.

    Values are raw (they span ~1e10): consumers must scale them robustly.
    """
    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"PHAC-2 data folder not found: {root}")
    arrays = _read_npz(_require(root / FEATURES_FILE))
    ids, names, adjectives, matrix = _read_objects(_require(root / OBJECTS_FILE))

    feats, obj, trial = arrays["features"], arrays["object_id"], arrays["trial"]
    if feats.ndim != 3 or feats.shape[1:] != (len(arrays["phases"]), len(arrays["feature_names"])):
        raise Phac2FormatError(
            f"features must be (N, phases={len(arrays['phases'])}, "
            f"features={len(arrays['feature_names'])}), got {feats.shape}"
        )
    n = len(feats)
    if obj.shape != (n,) or trial.shape != (n,):
        raise Phac2FormatError(f"object_id {obj.shape} and trial {trial.shape} must both be ({n},)")
    if not np.issubdtype(feats.dtype, np.number) or not np.isfinite(feats).all():
        raise Phac2FormatError("features contain NaN, infinite or non-numeric values")
    index = {oid: k for k, oid in enumerate(ids)}
    unknown = sorted(set(obj.tolist()) - index.keys())
    if unknown:
        raise Phac2FormatError(f"object ids {unknown[:5]} are not in {OBJECTS_FILE}")
    pairs = np.stack([obj, trial], axis=1).astype(np.int64)
    if len(np.unique(pairs, axis=0)) != n:
        raise Phac2FormatError("a (object_id, trial) pair occurs twice")

    if min_objects_per_attribute < 1:
        raise ValueError("min_objects_per_attribute must be >= 1")
    keep = matrix.sum(axis=0) >= min_objects_per_attribute
    if not keep.any():
        raise DatasetError(f"no adjective is present in >= {min_objects_per_attribute} objects")

    labels = np.array([index[o] for o in obj.tolist()], dtype=np.int64)
    # One group id per (object, trial): dense ranks keep ids small and unique.
    _, trials = np.unique(pairs, axis=0, return_inverse=True)
    return TactileDataset(
        samples=feats.reshape(n, -1).astype(np.float32),
        labels=labels,
        trials=trials,
        class_attributes=matrix[:, keep].astype(np.float32),
        attribute_names=tuple(a for a, k in zip(adjectives, keep, strict=True) if k),
        class_names=_unique_names(names, ids),
        object_ids=tuple(ids),
        name="phac2",
        procedures=tuple(str(p) for p in arrays["phases"].tolist()),
    )


def feature_names(path: str | Path) -> tuple[str, ...]:
    """The 188 flat feature names, "<phase>/<feature>", in sample column order."""
    arrays = _read_npz(_require(Path(path) / FEATURES_FILE))
    return tuple(
        f"{p}/{f}" for p in arrays["phases"].tolist() for f in arrays["feature_names"].tolist()
    )


def _unique_names(names: list[str], ids: list[int]) -> tuple[str, ...]:
    """PHAC-2 has two objects each named car_sponge, chalkboard_eraser and
    tooth_paste_box; a class is addressed by name, so those get their id appended."""
    counts = {n: names.count(n) for n in names}
    return tuple(f"{n}_{i}" if counts[n] > 1 else n for n, i in zip(names, ids, strict=True))
