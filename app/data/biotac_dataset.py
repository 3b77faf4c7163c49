"""``BioTacDataset``: raw trials of labelled objects, read from and written to a ``biotac:``
folder (one HDF5 file per object, optionally ``objects.csv``) by ``load_biotac`` and
``write_biotac_folder``."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.data.biotac_errors import RawTrialError
from app.data.biotac_h5 import read_biotac_h5, write_biotac_h5
from app.data.biotac_phases import PhaseRule
from app.data.biotac_trial import RawTrial
from app.data.dataset import DatasetError, DatasetFileError

_PRESSURE = re.compile(r"_pdc(\d+(?:\.\d+)?)(?:_|$)")
H5_SUFFIXES = (".h5", ".hdf5")
OBJECTS_FILE = "objects.csv"


@dataclass(frozen=True, eq=False)
class BioTacDataset:
    """Raw trials of labelled objects, as read from a ``biotac:`` folder.

    trials: the RawTrials; labels: int64 (n,), index of each trial's object in
    ``class_names``; trial_ids: int64 (n,), distinct per trial (hold-out splits use them);
    groups: each trial's "<file name>/<group name>"; grip_pressure: float64 (n,), the set
    pressure parsed from group names ``…_pdc<P>_…`` (NaN where a name has none);
    attribute_values: float32 (K, M), graded values in [0, 1] and NaN (not known) allowed,
    M = 0 without an objects.csv.
    """

    trials: tuple[RawTrial, ...]
    labels: np.ndarray
    trial_ids: np.ndarray
    class_names: tuple[str, ...]
    attribute_names: tuple[str, ...] = ()
    attribute_values: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.float32))
    groups: tuple[str, ...] = ()
    grip_pressure: np.ndarray = field(default_factory=lambda: np.zeros(0))
    name: str = "biotac"

    def __post_init__(self) -> None:
        n, k = len(self.trials), len(self.class_names)
        object.__setattr__(self, "trials", tuple(self.trials))
        object.__setattr__(self, "labels", np.asarray(self.labels, dtype=np.int64))
        object.__setattr__(self, "trial_ids", np.asarray(self.trial_ids, dtype=np.int64))
        object.__setattr__(self, "class_names", tuple(self.class_names))
        object.__setattr__(self, "attribute_names", tuple(self.attribute_names))
        values = np.asarray(self.attribute_values, dtype=np.float32)
        if values.size == 0 and not self.attribute_names:
            values = np.zeros((k, 0), np.float32)
        object.__setattr__(self, "attribute_values", values)
        object.__setattr__(
            self, "groups", tuple(self.groups) or tuple(f"trial {i}" for i in range(n))
        )
        pressure = np.asarray(self.grip_pressure, dtype=np.float64)
        object.__setattr__(self, "grip_pressure", pressure if pressure.size else np.full(n, np.nan))
        if n == 0:
            raise DatasetError(f"dataset '{self.name}' has no trials")
        for name in ("labels", "trial_ids", "grip_pressure"):
            if getattr(self, name).shape != (n,):
                raise DatasetError(f"{name} must be ({n},), got {getattr(self, name).shape}")
        if len(self.groups) != n:
            raise DatasetError(f"groups must have {n} entries, got {len(self.groups)}")
        if len(np.unique(self.trial_ids)) != n:
            raise DatasetError("trial_ids must be distinct")
        if self.labels.min() < 0 or self.labels.max() >= k:
            raise DatasetError(f"labels must lie in [0, {k})")
        if values.shape != (k, len(self.attribute_names)):
            raise DatasetError(
                f"attribute_values must be ({k}, {len(self.attribute_names)}), got {values.shape}"
            )

    def __len__(self) -> int:
        return len(self.trials)

    def __repr__(self) -> str:
        return (
            f"BioTacDataset(name={self.name!r}, trials={len(self)}, "
            f"classes={len(self.class_names)}, attributes={len(self.attribute_names)})"
        )

    @property
    def n_classes(self) -> int:
        return len(self.class_names)

    def subset(self, index: Any) -> BioTacDataset:
        """The trials selected by a boolean mask or index array; classes unchanged."""
        idx = np.arange(len(self))[np.asarray(index)]
        return BioTacDataset(
            trials=tuple(self.trials[i] for i in idx),
            labels=self.labels[idx],
            trial_ids=self.trial_ids[idx],
            class_names=self.class_names,
            attribute_names=self.attribute_names,
            attribute_values=self.attribute_values,
            groups=tuple(self.groups[i] for i in idx),
            grip_pressure=self.grip_pressure[idx],
            name=self.name,
        )


def pressure_from_group(name: str) -> float:
    """The set grip pressure in a pilot group name ``<object>_pdc<P>_1cm_<NN>``; NaN if none."""
    match = _PRESSURE.search(name)
    return float(match.group(1)) if match else math.nan


def load_biotac(
    path: str | Path, rule: PhaseRule | None = None, check_phases: bool = True
) -> BioTacDataset:
    """A ``biotac:`` folder: one HDF5 file per object (the object's name is the file's stem),
    one group per trial, and optionally ``objects.csv`` (``name,<attribute>,...``).

    Objects and their trials come in name order; trial ids are 0 … n-1 in that order. With
    ``check_phases``, every finger of a trial without phases must show them to ``rule``
    (default ``PhaseRule()``). Errors name the file and the group (RawTrialError) or the
    objects.csv row and field (DatasetFileError).
    """
    from app.data.folder import read_objects_csv

    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"BioTac data folder not found: {root}")
    files = sorted(p for p in root.iterdir() if p.suffix.lower() in H5_SUFFIXES and p.is_file())
    if not files:
        raise DatasetFileError(
            root,
            f"no HDF5 file ({', '.join(H5_SUFFIXES)}) in the folder; "
            "a biotac folder holds one file per object",
        )
    names = [p.stem for p in files]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise DatasetFileError(root, f"two files name object {repeated[0]!r}")
    trials, labels, groups, pressure = [], [], [], []
    for label, file in enumerate(files):
        for group, trial in read_biotac_h5(file).items():
            if check_phases:
                try:
                    trial.phase_bounds(rule)
                except RawTrialError as err:
                    raise err.located(file=str(file), group=group) from None
            trials.append(trial)
            labels.append(label)
            groups.append(f"{file.name}/{group}")
            pressure.append(pressure_from_group(group))
    attribute_names: tuple[str, ...] = ()
    values = np.zeros((len(names), 0), np.float32)
    if (root / OBJECTS_FILE).exists():
        table = read_objects_csv(root / OBJECTS_FILE)
        missing = [n for n in names if n not in table.names]
        if missing:
            raise DatasetFileError(
                root / OBJECTS_FILE,
                f"has no row for object {missing[0]!r} "
                f"(file {files[names.index(missing[0])].name})",
                field="name",
            )
        extra = [n for n in table.names if n not in names]
        if extra:
            row = table.names.index(extra[0]) + 2
            raise DatasetFileError(
                root / OBJECTS_FILE,
                f"object {extra[0]!r} has no file {extra[0]}.h5 in the folder",
                row=row,
                field="name",
            )
        attribute_names = table.attribute_names
        values = table.values[[table.names.index(n) for n in names]]
    return BioTacDataset(
        trials=tuple(trials),
        labels=np.array(labels),
        trial_ids=np.arange(len(trials)),
        class_names=tuple(names),
        attribute_names=attribute_names,
        attribute_values=values,
        groups=tuple(groups),
        grip_pressure=np.array(pressure),
        name="biotac",
    )


def write_biotac_folder(dataset: BioTacDataset, path: str | Path) -> None:
    """Write a dataset as a ``biotac:`` folder (one file per object; objects.csv when it has
    attributes). Group names are the part of ``groups`` after the file name."""
    from app.data.folder import write_objects_csv

    root = Path(path)
    root.mkdir(parents=True, exist_ok=True)
    for k, name in enumerate(dataset.class_names):
        rows = np.flatnonzero(dataset.labels == k)
        if len(rows) == 0:
            raise DatasetError(f"object {name!r} has no trial; a biotac folder cannot hold it")
        trials = {dataset.groups[i].rpartition("/")[2]: dataset.trials[i] for i in rows}
        write_biotac_h5(root / f"{name}.h5", trials)
    if dataset.attribute_names:
        write_objects_csv(
            root / OBJECTS_FILE,
            dataset.class_names,
            dataset.attribute_names,
            dataset.attribute_values,
        )
