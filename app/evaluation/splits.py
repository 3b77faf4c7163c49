"""Known/novel object splits with whole-trial hold-out (Sect. V-A and VI-A).

Each split draws ``n_novel`` novel objects Z; the other objects are the known set Y.
The draw is repeated (rejection sampling from ``numpy.random.default_rng(seed)``)
until it satisfies the paper's rules:

- the novel objects' attribute vectors are pairwise distinct (and not empty), so
  zero-shot learning can tell every novel object from the others. A novel
  object may share its vector with a known object, as in the paper's random
  splits (the data README asks only for distinct novel vectors); evaluation
  enrols such classes with ``allow_known_vectors=True`` and novelty detection
  separates them from their known twin. ``distinct_from_known=True`` demands
  vectors no known object has (only objects whose vector is unique in the
  dataset can then be novel);
- every attribute a novel object has is present in at least one known object
  (the known set "covers" Z), so each novel object shares at least one attribute
  with the known set and F and A are correlated for every attribute ZSL needs;
- no split repeats another split's novel set.

Test data is held out by whole trials, never one trial on both sides: of every
known object, ``test_trials`` trials (default 2 of 10) are held out as known test
data and the rest train. Of every novel object, one trial is the one-shot trial
(its first sample is the one-shot sample of Sect. VI-E) and all its other trials
are the novel test set, shared by the ZSL, OSL and mixed (GZSL) figures.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.data.dataset import TactileDataset


class SplitError(ValueError):
    """No split satisfying the rules can be drawn from this dataset with these settings."""


@dataclass(frozen=True)
class ZslSplit:
    """One known/novel split; all indices refer to the original dataset."""

    index: int  # 0-based position among the splits
    known_classes: np.ndarray  # dataset class indices of the known objects (sorted)
    novel_classes: np.ndarray  # dataset class indices of the novel objects (sorted)
    known_train_idx: np.ndarray  # sample indices: known objects' training trials
    known_test_idx: np.ndarray  # sample indices: known objects' held-out trials
    novel_test_idx: np.ndarray  # sample indices: novel objects' test trials
    one_shot_idx: np.ndarray  # one sample index per novel class, aligned with novel_classes
    novel_objects: tuple[int, ...]  # external object ids of the novel classes
    novel_names: tuple[str, ...]  # class names of the novel classes

    # ---------------------------------------------------------------- views
    def train_dataset(self, dataset: TactileDataset) -> TactileDataset:
        """The known objects' training trials, relabelled 0 … len(known_classes)-1."""
        return dataset.subset(self.known_train_idx).select_classes(self.known_classes)

    def known_labels(self, dataset: TactileDataset, idx: np.ndarray) -> np.ndarray:
        """Labels of known-object samples ``idx`` in the train dataset's numbering."""
        return _remap(dataset.n_classes, self.known_classes, dataset.labels[idx])

    def novel_labels(self, dataset: TactileDataset, idx: np.ndarray) -> np.ndarray:
        """Labels of novel-object samples ``idx`` numbered 0 … n_novel-1 as in novel_names."""
        return _remap(dataset.n_classes, self.novel_classes, dataset.labels[idx])

    def novel_attributes(self, dataset: TactileDataset) -> np.ndarray:
        return dataset.class_attributes[self.novel_classes]

    def describe(self, dataset: TactileDataset | None = None) -> dict:
        """JSON-ready summary; with the dataset, also the novel objects' attribute vectors."""
        out = {
            "index": self.index,
            "novel_objects": list(self.novel_objects),
            "novel_names": list(self.novel_names),
            "n_known_train": int(len(self.known_train_idx)),
            "n_known_test": int(len(self.known_test_idx)),
            "n_novel_test": int(len(self.novel_test_idx)),
        }
        if dataset is not None:
            out["novel_attributes"] = self.novel_attributes(dataset).astype(int).tolist()
        return out


def _remap(n_classes: int, classes: np.ndarray, labels: np.ndarray) -> np.ndarray:
    remap = np.full(n_classes, -1, dtype=np.int64)
    remap[classes] = np.arange(len(classes))
    out = remap[labels]
    if (out < 0).any():
        raise ValueError("some samples do not belong to the requested classes")
    return out


def novel_candidates(dataset: TactileDataset, distinct_from_known: bool = False) -> np.ndarray:
    """Classes that may be novel: a non-empty attribute vector, and with
    ``distinct_from_known`` one that no other class has."""
    attrs = dataset.class_attributes
    ok = attrs.sum(axis=1) > 0
    if distinct_from_known:
        _, inverse, counts = np.unique(attrs, axis=0, return_inverse=True, return_counts=True)
        ok &= counts[inverse.reshape(-1)] == 1
    return np.flatnonzero(ok)


def distinct_vectors(dataset: TactileDataset, classes: np.ndarray) -> bool:
    return len(np.unique(dataset.class_attributes[classes], axis=0)) == len(classes)


def covers(dataset: TactileDataset, known: np.ndarray, novel: np.ndarray) -> bool:
    """Every attribute of the novel objects is present in some known object."""
    attrs = dataset.class_attributes > 0.5
    known_union = attrs[known].any(axis=0)
    used = attrs[novel].any(axis=0)
    shares = (attrs[novel] & known_union).any(axis=1).all()
    return bool(shares and not (used & ~known_union).any())


def _trials_by_class(dataset: TactileDataset) -> dict[int, np.ndarray]:
    """Sorted trial ids of every class; a trial id shared by two classes is an error."""
    pairs = np.unique(np.stack([dataset.trials, dataset.labels], axis=1), axis=0)
    trial_ids, n_classes_of_trial = np.unique(pairs[:, 0], return_counts=True)
    if (n_classes_of_trial > 1).any():
        bad = int(trial_ids[np.argmax(n_classes_of_trial > 1)])
        raise SplitError(f"trial id {bad} holds samples of more than one class")
    return {c: pairs[pairs[:, 1] == c, 0] for c in range(dataset.n_classes)}


def make_zsl_splits(
    dataset: TactileDataset,
    n_novel: int,
    n_splits: int,
    seed: int,
    test_trials: int = 2,
    max_draws: int = 100_000,
    distinct_from_known: bool = False,
) -> list[ZslSplit]:
    """``n_splits`` splits with ``n_novel`` novel objects each; see the module docstring."""
    k = dataset.n_classes
    if not isinstance(n_novel, int | np.integer) or n_novel < 1:
        raise SplitError(f"n_novel must be a positive integer, got {n_novel!r}")
    if not isinstance(n_splits, int | np.integer) or n_splits < 1:
        raise SplitError(f"n_splits must be a positive integer, got {n_splits!r}")
    if not isinstance(test_trials, int | np.integer) or test_trials < 1:
        raise SplitError(f"test_trials must be a positive integer, got {test_trials!r}")
    if n_novel >= k - 1:
        raise SplitError(f"n_novel={n_novel} leaves fewer than 2 known objects of {k}")
    candidates = novel_candidates(dataset, distinct_from_known)
    trials = _trials_by_class(dataset)
    for c, t in trials.items():
        if len(t) == 0:
            raise SplitError(f"class '{dataset.class_names[c]}' has no samples")

    rng = np.random.default_rng(seed)
    novel_sets = draw_novel_sets(dataset, n_novel, n_splits, rng, max_draws, candidates)
    return [
        _hold_out(dataset, trials, i, np.setdiff1d(np.arange(k), novel), novel, test_trials, rng)
        for i, novel in enumerate(novel_sets)
    ]


def draw_novel_sets(
    dataset: TactileDataset,
    n_novel: int,
    n_sets: int,
    rng: np.random.Generator,
    max_draws: int = 100_000,
    candidates: np.ndarray | None = None,
) -> list[np.ndarray]:
    """``n_sets`` distinct sorted arrays of ``n_novel`` class indices obeying the split rules.

    Also used to carve validation objects out of a known set (hyper-parameter
    selection by baselines), so the same rules hold there.
    """
    if candidates is None:
        candidates = novel_candidates(dataset)
    n_distinct = len(np.unique(dataset.class_attributes[candidates], axis=0))
    if n_distinct < n_novel:
        raise SplitError(
            f"the eligible objects have only {n_distinct} distinct attribute vectors; "
            f"cannot pick {n_novel} novel objects with distinct vectors"
        )
    k = dataset.n_classes
    seen: set[tuple[int, ...]] = set()
    sets: list[np.ndarray] = []
    draws = 0
    while len(sets) < n_sets:
        draws += 1
        if draws > max_draws:
            raise SplitError(
                f"found only {len(sets)} of {n_sets} distinct valid splits with {n_novel} novel "
                f"objects after {max_draws} draws; ask for fewer splits or novel objects"
            )
        novel = np.sort(rng.choice(candidates, size=n_novel, replace=False)).astype(np.int64)
        key = tuple(int(c) for c in novel)
        if key in seen or not distinct_vectors(dataset, novel):
            continue
        if not covers(dataset, np.setdiff1d(np.arange(k), novel), novel):
            continue
        seen.add(key)
        sets.append(novel)
    return sets


def _hold_out(
    dataset: TactileDataset,
    trials: dict[int, np.ndarray],
    index: int,
    known: np.ndarray,
    novel: np.ndarray,
    test_trials: int,
    rng: np.random.Generator,
) -> ZslSplit:
    test_trial_ids: list[np.ndarray] = []
    for c in known:
        t = trials[int(c)]
        if len(t) <= test_trials:
            raise SplitError(
                f"known object '{dataset.class_names[c]}' has {len(t)} trials; holding out "
                f"{test_trials} would leave none to train on"
            )
        test_trial_ids.append(rng.choice(t, size=test_trials, replace=False))
    one_shot_trials = []
    for c in novel:
        t = trials[int(c)]
        if len(t) < 2:
            raise SplitError(
                f"novel object '{dataset.class_names[c]}' has {len(t)} trial; one-shot needs "
                "one trial for the sample and at least one to test on"
            )
        one_shot_trials.append(rng.choice(t))
    is_known = np.isin(dataset.labels, known)
    is_novel = ~is_known
    held = np.isin(dataset.trials, np.concatenate(test_trial_ids))
    one_shot_trial_mask = np.isin(dataset.trials, np.asarray(one_shot_trials))
    one_shot_idx = np.array(
        [np.flatnonzero(dataset.trials == t)[0] for t in one_shot_trials], dtype=np.int64
    )
    return ZslSplit(
        index=index,
        known_classes=known.astype(np.int64),
        novel_classes=novel.astype(np.int64),
        known_train_idx=np.flatnonzero(is_known & ~held),
        known_test_idx=np.flatnonzero(is_known & held),
        novel_test_idx=np.flatnonzero(is_novel & ~one_shot_trial_mask),
        one_shot_idx=one_shot_idx,
        novel_objects=tuple(dataset.object_ids[c] for c in novel),
        novel_names=tuple(dataset.class_names[c] for c in novel),
    )
