"""The one in-memory dataset form used by every other part of the package."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.data.procedures import ProcedureError, block, check_procedures


class DatasetError(ValueError):
    """A dataset is empty, inconsistent or malformed."""


class DatasetFileError(DatasetError):
    """A dataset file is missing, unreadable or malformed.

    ``file`` is the file's path, ``row`` the 1-based line of a CSV file (the header is line
    1) or the sample index in an array file, ``group`` an HDF5 group, ``field`` the column,
    key or dataset; those that do not apply are None. The message names all that are set.
    """

    def __init__(
        self,
        file: Any,
        reason: str,
        *,
        row: int | None = None,
        group: str | None = None,
        field: str | None = None,
    ) -> None:
        self.file, self.row, self.group, self.field = str(file), row, group, field
        self.reason = reason
        where = [self.file]
        if row is not None:
            where.append(f"row {row}")
        if group is not None:
            where.append(f"group {group!r}")
        if field is not None:
            where.append(f"field {field!r}")
        super().__init__(f"{', '.join(where)}: {reason}")


class _BinaryAttributeMatrix:
    """``TactileDataset.class_attributes``: the attribute matrix where every value is 0 or
    1, the only form the recognition methods can learn from; a DatasetError that says why
    where the dataset has graded or not-known values or no attribute at all. Every method
    reads this field, so none can train on such a dataset by mistake; code that handles
    graded values reads ``attribute_values``."""

    def __get__(self, obj: TactileDataset | None, objtype: type | None = None) -> np.ndarray:
        if obj is None:
            raise AttributeError("class_attributes has no default")  # a required field
        problem = obj.__dict__["_attribute_problem"]
        if problem:
            raise DatasetError(problem)
        return obj.__dict__["_attribute_values"]

    def __set__(self, obj: TactileDataset, value: Any) -> None:
        obj.__dict__["_attribute_values"] = value


@dataclass(frozen=True)
class TactileDataset:
    """Tactile samples of objects described by attributes.

    samples: float32, shape (N, C, T) for tactile images or (N, D) for flat features.
    labels: int64 (N,), index of the sample's class in ``class_names``.
    trials: int64 (N,), a group id shared by all samples of one exploration trial;
        hold-out splits never put one trial on both sides.
    class_attributes: float32 (K, M), row k describes class k. Given: values in [0, 1]
        (1 = has the attribute, graded values in between) or NaN (not known), and M may be
        0 (no attribute known). Read: the matrix when every value is 0 or 1 and M >= 1,
        else a DatasetError saying why: the recognition methods learn 0/1 attributes, so
        reading it is where a method meets a dataset it cannot use. ``attribute_values``
        always gives the matrix as given; ``binary_attributes`` says which case holds.
    attribute_names: the M attribute names, in column order.
    class_names: the K class names.
    object_ids: the K external object ids (PHAC-2 ids, or 0 … K-1 for simulated data).
    procedures: the exploratory procedures a sample holds, in order (PHAC-2's squeeze, hold,
        slide and move down), or () where the dataset does not name them. A sample's first
        axis splits into ``len(procedures)`` equal blocks, one per procedure
        (``app.data.procedures``): rows ``[j * r, (j + 1) * r)`` of an image or features
        ``[j * d, (j + 1) * d)`` of a flat vector.
    """

    samples: np.ndarray
    labels: np.ndarray
    trials: np.ndarray
    class_attributes: np.ndarray = _BinaryAttributeMatrix()  # type: ignore[assignment]
    attribute_names: tuple[str, ...]
    class_names: tuple[str, ...]
    object_ids: tuple[int, ...] = field(default=())
    name: str = "dataset"
    procedures: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        samples = np.ascontiguousarray(self.samples, dtype=np.float32)
        labels = np.asarray(self.labels, dtype=np.int64)
        trials = np.asarray(self.trials, dtype=np.int64)
        attrs = np.asarray(self.__dict__["_attribute_values"], dtype=np.float32)
        object.__setattr__(self, "samples", samples)
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "trials", trials)
        object.__setattr__(self, "class_attributes", attrs)
        object.__setattr__(self, "attribute_names", tuple(self.attribute_names))
        object.__setattr__(self, "class_names", tuple(self.class_names))
        object.__setattr__(self, "procedures", tuple(str(p) for p in self.procedures))
        if not self.object_ids:
            object.__setattr__(self, "object_ids", tuple(range(len(self.class_names))))
        else:
            object.__setattr__(self, "object_ids", tuple(int(i) for i in self.object_ids))
        self._validate()
        object.__setattr__(self, "_attribute_problem", self._why_not_binary())

    def _validate(self) -> None:
        n = len(self.samples)
        if n == 0:
            raise DatasetError(f"dataset '{self.name}' has no samples")
        if self.samples.ndim not in (2, 3):
            raise DatasetError(
                f"samples must have shape (N, C, T) or (N, D), got {self.samples.shape}"
            )
        if not np.isfinite(self.samples).all():
            raise DatasetError("samples contain NaN or infinite values")
        if self.labels.shape != (n,) or self.trials.shape != (n,):
            raise DatasetError(
                f"labels {self.labels.shape} and trials {self.trials.shape} must both be ({n},)"
            )
        k = len(self.class_names)
        attrs = self.attribute_values
        if attrs.shape != (k, len(self.attribute_names)):
            raise DatasetError(
                f"class_attributes must be ({k}, {len(self.attribute_names)}), got {attrs.shape}"
            )
        if len(set(self.class_names)) != k:
            dup = sorted({n for n in self.class_names if self.class_names.count(n) > 1})
            raise DatasetError(f"class names must be unique; repeated: {', '.join(dup)}")
        if len(set(self.attribute_names)) != len(self.attribute_names):
            names = self.attribute_names
            dup = sorted({a for a in names if names.count(a) > 1})
            raise DatasetError(f"attribute names must be unique; repeated: {', '.join(dup)}")
        if self.procedures:
            try:
                check_procedures(self.procedures, self.input_shape)
            except ProcedureError as exc:
                raise DatasetError(f"dataset '{self.name}': {exc}") from None
        if len(self.object_ids) != k:
            raise DatasetError(f"object_ids must have {k} entries, got {len(self.object_ids)}")
        if self.labels.min() < 0 or self.labels.max() >= k:
            raise DatasetError(
                f"labels must lie in [0, {k}), got [{self.labels.min()}, {self.labels.max()}]"
            )
        bad = ~(np.isnan(attrs) | ((attrs >= 0.0) & (attrs <= 1.0)))
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise DatasetError(
                f"class_attributes must lie in [0, 1] (NaN: not known); class "
                f"'{self.class_names[i]}', attribute '{self.attribute_names[j]}' is {attrs[i, j]}"
            )

    def _why_not_binary(self) -> str:
        """Why ``class_attributes`` cannot be read (empty when it can)."""
        attrs = self.attribute_values
        if attrs.shape[1] == 0:
            return (
                f"dataset '{self.name}' has no attributes; the recognition methods learn "
                "attributes for zero-shot recognition and need at least one attribute with a "
                "0/1 value for every class (e.g. an objects.csv with name,<attribute>,...)"
            )
        bad = ~np.isin(attrs, (0.0, 1.0))
        if not bad.any():
            return ""
        i, j = np.argwhere(bad)[0]
        value = "not known (empty)" if np.isnan(attrs[i, j]) else f"{attrs[i, j]:g}"
        return (
            f"dataset '{self.name}' has graded or not-known attribute values ({int(bad.sum())} "
            f"of {attrs.size}; class '{self.class_names[i]}', attribute "
            f"'{self.attribute_names[j]}' is {value}); the recognition methods learn 0/1 "
            "attributes: give every class 0 or 1 for every attribute"
        )

    @property
    def attribute_values(self) -> np.ndarray:
        """float32 (K, M): the attribute matrix as given, graded values and NaN included."""
        return self.__dict__["_attribute_values"]

    @property
    def binary_attributes(self) -> bool:
        """Every attribute value is 0 or 1 and there is at least one attribute: what
        ``class_attributes`` needs to be readable."""
        return not self.__dict__["_attribute_problem"]

    def __repr__(self) -> str:
        return (
            f"TactileDataset(name={self.name!r}, samples={self.samples.shape}, "
            f"classes={self.n_classes}, attributes={self.n_attributes}, "
            f"trials={len(np.unique(self.trials))})"
        )

    @property
    def input_shape(self) -> tuple[int, ...]:
        return tuple(self.samples.shape[1:])

    @property
    def n_classes(self) -> int:
        return len(self.class_names)

    @property
    def n_attributes(self) -> int:
        return len(self.attribute_names)

    def __len__(self) -> int:
        return len(self.samples)

    def subset(self, mask: np.ndarray) -> TactileDataset:
        """Samples selected by a boolean mask or index array; classes unchanged."""
        idx = np.asarray(mask)
        return TactileDataset(
            samples=self.samples[idx],
            labels=self.labels[idx],
            trials=self.trials[idx],
            class_attributes=self.attribute_values,
            attribute_names=self.attribute_names,
            class_names=self.class_names,
            object_ids=self.object_ids,
            name=self.name,
            procedures=self.procedures,
        )

    def with_attributes(
        self, attribute_names: Sequence[str], class_attributes: np.ndarray
    ) -> TactileDataset:
        """The same samples and classes described by other attributes: (K, M') values in
        [0, 1] or NaN (not known) for ``attribute_names``."""
        return TactileDataset(
            samples=self.samples,
            labels=self.labels,
            trials=self.trials,
            class_attributes=class_attributes,
            attribute_names=tuple(attribute_names),
            class_names=self.class_names,
            object_ids=self.object_ids,
            name=self.name,
            procedures=self.procedures,
        )

    def select_classes(self, classes: np.ndarray | list[int]) -> TactileDataset:
        """Samples of the given classes, relabelled 0 … len(classes)-1 in the given order."""
        classes = np.asarray(classes, dtype=np.int64)
        if len(np.unique(classes)) != len(classes):
            raise DatasetError("select_classes got a repeated class index")
        remap = np.full(self.n_classes, -1, dtype=np.int64)
        remap[classes] = np.arange(len(classes))
        keep = remap[self.labels] >= 0
        return TactileDataset(
            samples=self.samples[keep],
            labels=remap[self.labels[keep]],
            trials=self.trials[keep],
            class_attributes=self.attribute_values[classes],
            attribute_names=self.attribute_names,
            class_names=tuple(self.class_names[i] for i in classes),
            object_ids=tuple(self.object_ids[i] for i in classes),
            name=self.name,
            procedures=self.procedures,
        )

    def procedure_view(self, j: int) -> TactileDataset:
        """The same samples with only procedure ``j``'s block (``procedures[j]``)."""
        rows = block(self.procedures, self.input_shape, j)
        return TactileDataset(
            samples=self.samples[:, rows],
            labels=self.labels,
            trials=self.trials,
            class_attributes=self.attribute_values,
            attribute_names=self.attribute_names,
            class_names=self.class_names,
            object_ids=self.object_ids,
            name=f"{self.name}/{self.procedures[j]}",
            procedures=(self.procedures[j],),
        )
