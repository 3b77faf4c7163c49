"""An oracle recognizer whose figures are known exactly, registered as method "oracle"."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from app.data.dataset import TactileDataset
from app.data.simulator import simulate_dataset
from app.evaluation import protocol
from app.framework import registry
from app.framework.recognizer import NoveltyTuning, TactileRecognizer


def _key(x: np.ndarray) -> bytes:
    return np.ascontiguousarray(x, dtype=np.float32).tobytes()


class OracleRecognizer(TactileRecognizer):
    """Knows every sample's true class from ``truth``; with ``wrong=True`` enrolment it
    always answers the first novel class. Records what it was given."""

    method = "oracle"
    truth: dict[bytes, str] = {}
    seen_training: list[set[bytes]] = []  # one set per fit (= per split)
    one_shots: list[tuple[str, bytes]] = []

    def _fit(self, dataset: TactileDataset, progress: bool) -> None:
        OracleRecognizer.seen_training.append({_key(x) for x in dataset.samples})
        self.novelty_tuning = NoveltyTuning(
            thresholds=np.array([0.0, 0.5, 1.0]),
            known_kept=np.array([0.2, 0.9, 1.0]),
            val_novel=np.array([1.0, 0.7, 0.0]),
            threshold=0.5,
            known_kept_at_threshold=0.9,
            val_novel_at_threshold=0.7,
        )
        self.novelty_threshold = 0.5
        self.wrong = False

    def _names(self, samples):
        return [self.truth[_key(x)] for x in samples]

    def _one_hot(self, samples, classes):
        out = np.full((len(samples), len(classes)), 0.0)
        for i, name in enumerate(self._names(samples)):
            if name in classes:
                out[i, classes.index(name)] = 1.0
            else:
                out[i] = 1.0 / len(classes)
        return out

    def _known_proba(self, samples):
        return self._one_hot(samples, self.registry.known_names)

    def _novel_proba(self, samples):
        if self.wrong:
            out = np.zeros((len(samples), len(self.registry.novel_names)))
            out[:, 0] = 1.0
            return out
        return self._one_hot(samples, self.registry.novel_names)

    def _novelty_score(self, samples):
        known = set(self.registry.known_names)
        return np.array([0.0 if n in known else 1.0 for n in self._names(samples)])

    def _refit_novel(self, wrong: bool = False, **options: Any) -> None:
        self.wrong = wrong
        for name, samples in self.registry.novel_samples.items():
            for x in samples:
                OracleRecognizer.one_shots.append((name, _key(x)))

    def get_state(self):
        return {}, {}

    def set_state(self, meta, arrays):
        pass


@pytest.fixture()
def oracle(monkeypatch):
    ds = simulate_dataset(n_objects=16, trials_per_object=5, seed=1)
    attrs = ds.class_attributes.copy()
    attrs[1:4] = attrs[0]  # objects 0-3 are twins: at most one of them is novel in a split
    ds = replace(ds, class_attributes=attrs)
    OracleRecognizer.truth = {
        _key(x): ds.class_names[y] for x, y in zip(ds.samples, ds.labels, strict=True)
    }
    OracleRecognizer.seen_training = []
    OracleRecognizer.one_shots = []
    monkeypatch.setitem(
        registry.METHODS, "oracle", f"{OracleRecognizer.__module__}:OracleRecognizer"
    )
    monkeypatch.setitem(
        protocol.ZSL_VARIANTS, "oracle", {"zsl_wrong": {"wrong": True}, "zsl_same": None}
    )
    return ds
