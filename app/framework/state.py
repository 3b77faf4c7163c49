"""The state every recognizer carries besides its method's own parts: its classes
(``ClassRegistry``) and how its novelty threshold was chosen (``NoveltyTuning``). A model
bundle stores both."""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from app.framework.defaults import DEFAULT_KNOWN_KEPT
from app.framework.errors import UnknownClassError

__all__ = ["DEFAULT_KNOWN_KEPT", "KNOWN_KEPT", "MODEL_DEFAULT", "ClassRegistry", "NoveltyTuning"]
#: ``operating_point`` of an answer: routed by a stated share of known touches kept, or by
#: the model's own threshold (a model without a calibration curve, or asked for none)
KNOWN_KEPT, MODEL_DEFAULT = "known_kept", "model_default"


@dataclass
class NoveltyTuning:
    """How the novelty threshold was chosen (Sect. VI-B, Fig. 7)."""

    thresholds: np.ndarray
    known_kept: np.ndarray  # accuracy of calling held-out known samples known, per threshold
    val_novel: np.ndarray  # accuracy of calling validation-novel samples novel, per threshold
    threshold: float
    known_kept_at_threshold: float
    val_novel_at_threshold: float
    auroc: float = float("nan")

    def threshold_keeping(self, kept: float) -> float:
        """The lowest threshold of the curve that keeps at least the share ``kept`` of the
        held-out known samples known (the highest where none keeps that many): an operating
        point read off the curve, to its resolution (``thresholds``: up to 200 quantiles)."""
        i = int(np.searchsorted(self.known_kept, kept, side="left"))
        return float(self.thresholds[min(i, len(self.thresholds) - 1)])

    def to_dict(self) -> dict[str, Any]:
        return {
            "thresholds": self.thresholds.tolist(),
            "known_kept": self.known_kept.tolist(),
            "val_novel": self.val_novel.tolist(),
            "threshold": self.threshold,
            "known_kept_at_threshold": self.known_kept_at_threshold,
            "val_novel_at_threshold": self.val_novel_at_threshold,
            "auroc": self.auroc,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> NoveltyTuning:
        return cls(
            thresholds=np.asarray(d["thresholds"], dtype=np.float64),
            known_kept=np.asarray(d["known_kept"], dtype=np.float64),
            val_novel=np.asarray(d["val_novel"], dtype=np.float64),
            threshold=float(d["threshold"]),
            known_kept_at_threshold=float(d["known_kept_at_threshold"]),
            val_novel_at_threshold=float(d["val_novel_at_threshold"]),
            auroc=float(d.get("auroc", float("nan"))),
        )


@dataclass
class ClassRegistry:
    """Known and novel classes with their attribute vectors, and novel classes' real samples."""

    attribute_names: tuple[str, ...] = ()
    known_names: list[str] = field(default_factory=list)
    known_attributes: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.float32))
    novel_names: list[str] = field(default_factory=list)
    novel_attributes: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.float32))
    # real samples that arrived for novel classes (one-shot learning), by class name
    novel_samples: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def all_names(self) -> list[str]:
        return self.known_names + self.novel_names

    def __deepcopy__(self, memo: dict) -> ClassRegistry:
        # Class names are strings, which a deep copy shares anyway: a copy of each list is
        # its deep copy, without copy.deepcopy visiting every name (~3 ms a registry at
        # 10,000 classes; an enrolment of best copies its own and each procedure model's
        # registry, 13 of them: 37 ms of its 38).
        out = copy.copy(self)
        memo[id(self)] = out
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name.endswith("_names") and type(value) in (list, tuple):
                setattr(out, f.name, type(value)(value))
            else:
                setattr(out, f.name, copy.deepcopy(value, memo))
        return out

    def kind_of(self, name: str) -> str:
        if name in self.known_names:
            return "known"
        if name in self.novel_names:
            return "novel"
        raise UnknownClassError(f"unknown class '{name}'")
