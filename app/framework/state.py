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
    """How the novelty threshold was chosen (Sect. VI-B, Fig. 7), and the calibration curves
    operating points are read off.

    ``thresholds`` / ``known_kept``: the curve of single held-out known samples. ``touches``:
    where fitting measured them, the curves of answers that fuse k touches (k held-out
    trials of one known object, their novelty scores averaged as ``fuse_groups`` does; for
    a raw-trial model a touch is a trial, all its images): ``{k: (thresholds, known_kept)}``.
    A fused score varies less than a single one, so the single curve's threshold keeps more
    fused answers known than it states (PHAC-2: 0.90 stated, 0.96 kept at 3 touches)."""

    thresholds: np.ndarray
    known_kept: np.ndarray  # accuracy of calling held-out known samples known, per threshold
    val_novel: np.ndarray  # accuracy of calling validation-novel samples novel, per threshold
    threshold: float
    known_kept_at_threshold: float
    val_novel_at_threshold: float
    auroc: float = float("nan")
    touches: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)

    def threshold_keeping(self, kept: float) -> float:
        """The lowest threshold of the curve that keeps at least the share ``kept`` of the
        held-out known samples known (the highest where none keeps that many): an operating
        point read off the curve, to its resolution (``thresholds``: up to 200 quantiles)."""
        return _read_off(self.thresholds, self.known_kept, kept)

    def curve_for(self, touches: int) -> int:
        """The number of fused touches whose curve serves answers fusing ``touches``: the
        largest measured that is not more (0: the single samples' curve). Fewer touches'
        curve keeps at least its stated share of answers fusing more."""
        return max((k for k in self.touches if k <= touches), default=0)

    def threshold_keeping_touches(self, kept: float, touches: int) -> tuple[float, int]:
        """(threshold, k): the threshold keeping ``kept`` of held-out known answers that
        fuse ``touches`` touches, read off the curve of k = ``curve_for(touches)`` fused
        touches (0: the single samples' curve, ``threshold_keeping``)."""
        k = self.curve_for(touches)
        if k == 0:
            return self.threshold_keeping(kept), 0
        thresholds, known_kept = self.touches[k]
        return _read_off(thresholds, known_kept, kept), k

    def to_dict(self) -> dict[str, Any]:
        out = {
            "thresholds": self.thresholds.tolist(),
            "known_kept": self.known_kept.tolist(),
            "val_novel": self.val_novel.tolist(),
            "threshold": self.threshold,
            "known_kept_at_threshold": self.known_kept_at_threshold,
            "val_novel_at_threshold": self.val_novel_at_threshold,
            "auroc": self.auroc,
        }
        if self.touches:
            out["touches"] = {
                str(k): {"thresholds": t.tolist(), "known_kept": q.tolist()}
                for k, (t, q) in sorted(self.touches.items())
            }
        return out

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
            # a bundle written before 2026-11-28 holds the single samples' curve alone
            touches={
                int(k): (
                    np.asarray(c["thresholds"], dtype=np.float64),
                    np.asarray(c["known_kept"], dtype=np.float64),
                )
                for k, c in (d.get("touches") or {}).items()
            },
        )


def _read_off(thresholds: np.ndarray, known_kept: np.ndarray, kept: float) -> float:
    """The lowest of ``thresholds`` (ascending) whose ``known_kept`` reaches ``kept``; the
    highest where none does."""
    i = int(np.searchsorted(known_kept, kept, side="left"))
    return float(thresholds[min(i, len(thresholds) - 1)])


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
