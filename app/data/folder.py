"""The ``folder:`` dataset format: fixed-shape samples in three plain files.

- ``objects.csv``: header ``name,<attribute>,...`` (or ``object_id,name,<attribute>,...``
  to keep external object ids), one row per object; attribute values 0/1 or graded in
  [0, 1], an empty cell meaning not known; attribute columns may be absent.
- ``samples.npy``: float array ``(N, *input_shape)``, input shape (D,) or (C, T).
- ``samples.csv``: header ``object,trial``, N rows in samples.npy order: the object's name
  and an integer trial id. Samples of one object that share a trial id are one
  exploration and are never split between training and test. Trials may be numbered per
  object (trial 1 of every object, as PHAC-2 and most recordings number them) or across
  the file; a trial is the pair (object, trial), and trial ids numbered per object are
  renumbered across the dataset in the order the pairs first appear.
- ``procedures.txt`` (optional): the exploratory procedures a sample holds along its first
  axis, one name per line in order; samples then have shape ``(P, ...)`` (or a first axis
  of P equal blocks, ``app.data.procedures``), and a model fitted on them answers samples
  that lack some procedures.

Every error is a DatasetFileError naming the file, the row (the CSV line, header = 1; the
sample index in samples.npy) and the field. See docs/DATASETS.md.
"""

from __future__ import annotations

import csv
import math
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.data.dataset import DatasetFileError, TactileDataset
from app.data.procedures import ProcedureError, check_procedures

OBJECTS_FILE = "objects.csv"
SAMPLES_NPY = "samples.npy"
SAMPLES_CSV = "samples.csv"
PROCEDURES_FILE = "procedures.txt"
FILES = (OBJECTS_FILE, SAMPLES_NPY, SAMPLES_CSV)
_SAMPLE_HEADER = ["object", "trial"]


@dataclass(frozen=True, eq=False)
class ObjectTable:
    """The rows of an objects.csv: names, attribute names, the (K, M) float32 values (NaN:
    not known) and the object ids when the file has an ``object_id`` column."""

    names: tuple[str, ...]
    attribute_names: tuple[str, ...]
    values: np.ndarray
    object_ids: tuple[int, ...] | None = None


def _read_rows(path: Path) -> list[tuple[int, list[str]]]:
    """(line number, cells) of every non-blank line of a CSV file."""
    if not path.is_file():
        raise DatasetFileError(path, "file not found")
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:
            rows = [(i, [c.strip() for c in row]) for i, row in enumerate(csv.reader(fh), 1)]
    except (UnicodeDecodeError, csv.Error) as exc:
        raise DatasetFileError(path, f"not a readable CSV file: {exc}") from None
    return [(i, row) for i, row in rows if any(row)]


def read_objects_csv(path: str | Path) -> ObjectTable:
    """Parse an objects.csv; DatasetFileError names the file, the row and the field."""
    path = Path(path)
    rows = _read_rows(path)
    if not rows:
        raise DatasetFileError(path, "is empty; expected a header name,<attribute>,...", row=1)
    line, header = rows[0]
    with_ids = header[:2] == ["object_id", "name"]
    if not with_ids and header[:1] != ["name"]:
        raise DatasetFileError(
            path,
            f"the header must start with 'name' (or 'object_id,name'), got {','.join(header)!r}",
            row=line,
            field=header[0],
        )
    first = 2 if with_ids else 1
    attributes = header[first:]
    seen: set[str] = set()
    for a in attributes:
        if not a:
            raise DatasetFileError(path, "an attribute column has an empty name", row=line)
        if a in seen or a in ("name", "object_id"):
            raise DatasetFileError(path, "repeated column name", row=line, field=a)
        seen.add(a)
    names: list[str] = []
    ids: list[int] = []
    values = np.full((len(rows) - 1, len(attributes)), np.nan, np.float32)
    for k, (line, row) in enumerate(rows[1:]):
        if len(row) != len(header):
            raise DatasetFileError(
                path, f"has {len(row)} cells where the header has {len(header)}", row=line
            )
        name = row[first - 1]
        if not name:
            raise DatasetFileError(path, "the object name is empty", row=line, field="name")
        if name in names:
            raise DatasetFileError(
                path,
                f"object {name!r} is repeated (first at row {rows[names.index(name) + 1][0]})",
                row=line,
                field="name",
            )
        names.append(name)
        if with_ids:
            try:
                ids.append(int(row[0]))
            except ValueError:
                raise DatasetFileError(
                    path, f"{row[0]!r} is not an integer", row=line, field="object_id"
                ) from None
            if ids[-1] in ids[:-1]:
                raise DatasetFileError(
                    path, f"object_id {ids[-1]} is repeated", row=line, field="object_id"
                )
        for j, (attribute, cell) in enumerate(zip(attributes, row[first:], strict=True)):
            if cell == "":
                continue  # not known
            try:
                v = float(cell)
            except ValueError:
                v = math.nan
            if not 0.0 <= v <= 1.0:
                raise DatasetFileError(
                    path,
                    f"{cell!r} is not a value in [0, 1] (1: has it, 0: "
                    "has not, graded in between, empty: not known)",
                    row=line,
                    field=attribute,
                )
            values[k, j] = v
    if not names:
        raise DatasetFileError(path, "has a header but no object row", row=line + 1)
    return ObjectTable(tuple(names), tuple(attributes), values, tuple(ids) if with_ids else None)


def write_objects_csv(
    path: str | Path,
    names: Sequence[str],
    attribute_names: Sequence[str],
    values: np.ndarray,
    object_ids: Sequence[int] | None = None,
) -> None:
    """Write an objects.csv that ``read_objects_csv`` reads back to the same float32 values
    (NaN as an empty cell)."""
    with Path(path).open("w", newline="", encoding="utf-8") as fh:
        out = csv.writer(fh, lineterminator="\n")
        lead = ["object_id", "name"] if object_ids is not None else ["name"]
        out.writerow(lead + list(attribute_names))
        for k, name in enumerate(names):
            cells = [_cell(v) for v in np.asarray(values[k], dtype=np.float32)]
            first = [int(object_ids[k]), name] if object_ids is not None else [name]
            out.writerow(first + cells)


def _cell(value: np.float32) -> str:
    """The shortest text that reads back as the same float32 ("1", "0", "0.1"); NaN: empty."""
    return "" if np.isnan(value) else np.format_float_positional(value, trim="-")


def load_folder(path: str | Path) -> TactileDataset:
    """A ``folder:`` dataset (module docstring) as a TactileDataset named 'folder'.

    Classes come in objects.csv order; attribute values are kept as given (graded and not
    known included, see ``TactileDataset.class_attributes``).
    """
    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"dataset folder not found: {root}")
    table = read_objects_csv(root / OBJECTS_FILE)
    samples = _read_samples(root / SAMPLES_NPY)
    labels, trials = _read_sample_rows(root / SAMPLES_CSV, table.names)
    if len(labels) != len(samples):
        raise DatasetFileError(
            root / SAMPLES_CSV,
            f"has {len(labels)} sample rows where {SAMPLES_NPY} has {len(samples)} samples",
        )
    bad = ~np.isfinite(samples.reshape(len(samples), -1)).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise DatasetFileError(
            root / SAMPLES_NPY,
            f"sample {i} (line {i + 2} of {SAMPLES_CSV}) contains NaN or infinity",
            row=i,
        )
    procedures = _read_procedures(root / PROCEDURES_FILE, samples.shape[1:])
    return TactileDataset(
        samples=samples,
        labels=labels,
        trials=trials,
        class_attributes=table.values,
        attribute_names=table.attribute_names,
        class_names=table.names,
        object_ids=table.object_ids or (),
        name="folder",
        procedures=procedures,
    )


def _read_procedures(path: Path, input_shape: tuple[int, ...]) -> tuple[str, ...]:
    """The names in procedures.txt (none when the file is absent), checked against the
    samples' shape."""
    if not path.is_file():
        return ()
    try:
        names = tuple(line.strip() for line in path.read_text("utf-8-sig").splitlines())
    except UnicodeDecodeError as exc:
        raise DatasetFileError(path, f"not a readable text file: {exc}") from None
    names = tuple(n for n in names if n)
    try:
        check_procedures(names, input_shape)
    except ProcedureError as exc:
        raise DatasetFileError(path, f"{exc} (samples have shape {list(input_shape)})") from None
    return names


def _read_samples(path: Path) -> np.ndarray:
    if not path.is_file():
        raise DatasetFileError(path, "file not found")
    try:
        x = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise DatasetFileError(path, f"not a readable .npy array: {exc}") from None
    if not isinstance(x, np.ndarray):
        raise DatasetFileError(path, "holds several arrays (an .npz); expected one .npy array")
    if x.dtype.kind not in "iuf":
        raise DatasetFileError(path, f"must hold numbers, holds {x.dtype}")
    if x.ndim not in (2, 3) or len(x) == 0:
        raise DatasetFileError(
            path, f"must have shape (N, D) or (N, C, T) with N >= 1, got {x.shape}"
        )
    return x.astype(np.float32, copy=False)


def _read_sample_rows(path: Path, objects: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    rows = _read_rows(path)
    if not rows or rows[0][1] != _SAMPLE_HEADER:
        got = ",".join(rows[0][1]) if rows else ""
        raise DatasetFileError(
            path, f"the header must be 'object,trial', got {got!r}", row=rows[0][0] if rows else 1
        )
    index = {name: k for k, name in enumerate(objects)}
    labels, trials = [], []
    for line, row in rows[1:]:
        if len(row) != 2:
            raise DatasetFileError(path, f"has {len(row)} cells where the header has 2", row=line)
        name, trial = row
        if name not in index:
            raise DatasetFileError(
                path, f"object {name!r} is not in {OBJECTS_FILE}", row=line, field="object"
            )
        try:
            t = int(trial)
        except ValueError:
            raise DatasetFileError(
                path, f"trial {trial!r} is not an integer", row=line, field="trial"
            ) from None
        labels.append(index[name])
        trials.append(t)
    labels_a, trials_a = np.array(labels, dtype=np.int64), np.array(trials, dtype=np.int64)
    pairs, first, ids = np.unique(
        np.stack([labels_a, trials_a], axis=1), axis=0, return_index=True, return_inverse=True
    )
    if len(np.unique(pairs[:, 1])) < len(pairs):  # ids numbered per object: one per pair
        order = np.argsort(np.argsort(first))  # pairs numbered in the order they appear
        trials_a = order[ids.ravel()].astype(np.int64)
    return labels_a, trials_a


def write_folder(dataset: TactileDataset, path: str | Path, overwrite: bool = False) -> Path:
    """Write ``dataset`` as a ``folder:`` dataset that ``load_folder`` reads back with the
    same samples, labels, trials, attribute values, names and object ids. Existing files
    of the format are kept (FileExistsError) unless ``overwrite``."""
    root = Path(path)
    root.mkdir(parents=True, exist_ok=True)
    present = [f for f in FILES if (root / f).exists()]
    if present and not overwrite:
        raise FileExistsError(
            f"{root} already holds {', '.join(present)}; choose an empty folder or overwrite"
        )
    k = dataset.n_classes
    ids = None if dataset.object_ids == tuple(range(k)) else dataset.object_ids
    write_objects_csv(
        root / OBJECTS_FILE,
        dataset.class_names,
        dataset.attribute_names,
        dataset.attribute_values,
        ids,
    )
    np.save(root / SAMPLES_NPY, dataset.samples.astype(np.float32), allow_pickle=False)
    if dataset.procedures:
        (root / PROCEDURES_FILE).write_text("".join(f"{p}\n" for p in dataset.procedures), "utf-8")
    else:
        (root / PROCEDURES_FILE).unlink(missing_ok=True)
    with (root / SAMPLES_CSV).open("w", newline="", encoding="utf-8") as fh:
        out = csv.writer(fh, lineterminator="\n")
        out.writerow(_SAMPLE_HEADER)
        out.writerows(
            zip(
                [dataset.class_names[i] for i in dataset.labels.tolist()],
                dataset.trials.tolist(),
                strict=True,
            )
        )
    return root
