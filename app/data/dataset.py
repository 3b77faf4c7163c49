"""The one in-memory dataset form used by every other part of the package."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


class DatasetError(ValueError):
    """A dataset is empty, inconsistent or malformed."""


@dataclass(frozen=True)
class TactileDataset:
    """Tactile samples of objects described by binary attributes.

    samples: float32, shape (N, C, T) for tactile images or (N, D) for flat features.
    labels: int64 (N,), index of the sample's class in ``class_names``.
    trials: int64 (N,), a group id shared by all samples of one exploration trial;
        hold-out splits never put one trial on both sides.
    class_attributes: float32 (K, M) 0/1 matrix, row k describes class k.
    attribute_names: the M attribute names, in column order.
    class_names: the K class names.
    object_ids: the K external object ids (PHAC-2 ids, or 0 … K-1 for simulated data).
    """

    samples: np.ndarray
    labels: np.ndarray
    trials: np.ndarray
    class_attributes: np.ndarray
    attribute_names: tuple[str, ...]
    class_names: tuple[str, ...]
    object_ids: tuple[int, ...] = field(default=())
    name: str = "dataset"

    def __post_init__(self) -> None:
        samples = np.ascontiguousarray(self.samples, dtype=np.float32)
        labels = np.asarray(self.labels, dtype=np.int64)
        trials = np.asarray(self.trials, dtype=np.int64)
        attrs = np.asarray(self.class_attributes, dtype=np.float32)
        object.__setattr__(self, "samples", samples)
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "trials", trials)
        object.__setattr__(self, "class_attributes", attrs)
        object.__setattr__(self, "attribute_names", tuple(self.attribute_names))
        object.__setattr__(self, "class_names", tuple(self.class_names))
        if not self.object_ids:
            object.__setattr__(self, "object_ids", tuple(range(len(self.class_names))))
        else:
            object.__setattr__(self, "object_ids", tuple(int(i) for i in self.object_ids))
        self._validate()

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
        if self.class_attributes.shape != (k, len(self.attribute_names)):
            raise DatasetError(
                f"class_attributes must be ({k}, {len(self.attribute_names)}), "
                f"got {self.class_attributes.shape}"
            )
        if len(set(self.class_names)) != k:
            dup = sorted({n for n in self.class_names if self.class_names.count(n) > 1})
            raise DatasetError(f"class names must be unique; repeated: {', '.join(dup)}")
        if len(self.object_ids) != k:
            raise DatasetError(f"object_ids must have {k} entries, got {len(self.object_ids)}")
        if self.labels.min() < 0 or self.labels.max() >= k:
            raise DatasetError(f"labels must lie in [0, {k}), got [{self.labels.min()}, {self.labels.max()}]")
        if not np.isin(self.class_attributes, (0.0, 1.0)).all():
            raise DatasetError("class_attributes must contain only 0 and 1")

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
            class_attributes=self.class_attributes,
            attribute_names=self.attribute_names,
            class_names=self.class_names,
            object_ids=self.object_ids,
            name=self.name,
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
            class_attributes=self.class_attributes[classes],
            attribute_names=self.attribute_names,
            class_names=tuple(self.class_names[i] for i in classes),
            object_ids=tuple(self.object_ids[i] for i in classes),
            name=self.name,
        )
