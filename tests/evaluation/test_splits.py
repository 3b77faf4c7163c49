"""Split rules: distinct novel vectors, covered attributes, whole-trial hold-out, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from app.data.dataset import TactileDataset
from app.data.simulator import simulate_dataset
from app.evaluation.splits import SplitError, covers, make_zsl_splits, novel_candidates

# 10 objects, 5 attributes. Objects 0 and 1 share a vector; object 9 alone has attribute 4.
ATTRS = np.array(
    [
        [1, 0, 0, 0, 0],
        [1, 0, 0, 0, 0],
        [1, 1, 0, 0, 0],
        [0, 1, 0, 0, 0],
        [0, 1, 1, 0, 0],
        [0, 0, 1, 0, 0],
        [0, 0, 1, 1, 0],
        [0, 0, 0, 1, 0],
        [1, 0, 0, 1, 0],
        [0, 0, 0, 1, 1],
    ],
    dtype=np.float32,
)


def handmade(trials_per_object: int = 5, samples_per_trial: int = 1, attrs=ATTRS) -> TactileDataset:
    k = len(ATTRS)
    labels = np.repeat(np.arange(k), trials_per_object * samples_per_trial)
    trials = np.repeat(np.arange(k * trials_per_object), samples_per_trial) + 100
    rng = np.random.default_rng(0)
    return TactileDataset(
        samples=rng.normal(size=(len(labels), 4)),
        labels=labels,
        trials=trials,
        class_attributes=attrs,
        attribute_names=tuple("abcde"),
        class_names=tuple(f"o{i}" for i in range(k)),
        object_ids=tuple(200 + i for i in range(k)),
    )


def test_candidates_and_rules():
    ds = handmade()
    assert set(novel_candidates(ds)) == set(range(10))
    assert set(novel_candidates(ds, distinct_from_known=True)) == set(range(2, 10))
    assert not covers(ds, np.arange(9), np.array([9]))  # attribute e only in object 9
    assert covers(ds, np.setdiff1d(np.arange(10), [3, 5]), np.array([3, 5]))


@pytest.mark.parametrize("n_novel", [1, 2, 3])
@pytest.mark.parametrize("strict", [False, True])
def test_every_split_obeys_the_rules(n_novel, strict):
    ds = handmade()
    splits = make_zsl_splits(ds, n_novel=n_novel, n_splits=6, seed=3, distinct_from_known=strict)
    assert len({tuple(s.novel_classes) for s in splits}) == 6  # no repeated split
    for s in splits:
        novel, known = s.novel_classes, s.known_classes
        assert len(novel) == n_novel and len(np.intersect1d(novel, known)) == 0
        assert len(novel) + len(known) == ds.n_classes
        vecs = ATTRS[novel]
        assert len(np.unique(vecs, axis=0)) == n_novel  # pairwise distinct
        if strict:  # distinct from every known vector too
            for v in vecs:
                assert not (ATTRS[known] == v).all(axis=1).any()
            assert 0 not in novel and 1 not in novel
        union = ATTRS[known].max(axis=0)
        assert ((vecs <= union).all()) and ((vecs * union).sum(axis=1) > 0).all()
        assert 9 not in novel  # its attribute e would not be covered by the known set
        assert s.novel_objects == tuple(200 + c for c in novel)
        assert s.novel_names == tuple(f"o{c}" for c in novel)


def test_objects_sharing_a_vector_are_never_both_novel():
    ds = handmade()
    splits = make_zsl_splits(ds, n_novel=5, n_splits=40, seed=0)
    assert any(0 in s.novel_classes or 1 in s.novel_classes for s in splits)
    assert not any({0, 1} <= set(s.novel_classes) for s in splits)


def test_whole_trials_held_out_and_one_shot_trial_excluded():
    ds = handmade(trials_per_object=5, samples_per_trial=3)
    for s in make_zsl_splits(ds, n_novel=2, n_splits=4, seed=1, test_trials=2):
        train_t = set(ds.trials[s.known_train_idx])
        test_t = set(ds.trials[s.known_test_idx])
        novel_t = set(ds.trials[s.novel_test_idx])
        shot_t = set(ds.trials[s.one_shot_idx])
        assert not train_t & test_t and not shot_t & novel_t
        assert not (train_t | test_t) & (novel_t | shot_t)
        for c in s.known_classes:  # 2 of 5 trials of every known object are test trials
            held = set(ds.trials[s.known_test_idx][ds.labels[s.known_test_idx] == c])
            assert len(held) == 2
            assert len(set(ds.trials[ds.labels == c]) - held) == 3
        # one one-shot sample per novel object, from its own object; the rest of that
        # object's trials (4 of 5, every sample) are its test set
        assert list(ds.labels[s.one_shot_idx]) == list(s.novel_classes)
        for c in s.novel_classes:
            assert (ds.labels[s.novel_test_idx] == c).sum() == 4 * 3
        covered = np.concatenate([s.known_train_idx, s.known_test_idx, s.novel_test_idx])
        assert len(np.unique(covered)) == len(covered) == len(ds) - 2 * 3
        # relabelling helpers agree with the train dataset's class order
        train = s.train_dataset(ds)
        assert train.class_names == tuple(ds.class_names[c] for c in s.known_classes)
        yk = s.known_labels(ds, s.known_test_idx)
        assert [train.class_names[j] for j in yk] == [
            ds.class_names[c] for c in ds.labels[s.known_test_idx]
        ]
        yn = s.novel_labels(ds, s.novel_test_idx)
        assert [s.novel_names[j] for j in yn] == [
            ds.class_names[c] for c in ds.labels[s.novel_test_idx]
        ]


def test_deterministic_under_seed():
    ds = handmade()
    a = make_zsl_splits(ds, 2, 3, seed=7)
    b = make_zsl_splits(ds, 2, 3, seed=7)
    c = make_zsl_splits(ds, 2, 3, seed=8)
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x.novel_classes, y.novel_classes)
        assert np.array_equal(x.known_test_idx, y.known_test_idx)
        assert np.array_equal(x.one_shot_idx, y.one_shot_idx)
    assert any(
        not np.array_equal(x.novel_classes, y.novel_classes)
        or not np.array_equal(x.known_test_idx, y.known_test_idx)
        for x, y in zip(a, c, strict=True)
    )


def test_impossible_requests_raise_clear_errors():
    ds = handmade()
    shared = ATTRS.copy()
    shared[2:6] = ATTRS[0]  # objects 0-5 share one vector: 5 distinct vectors in all
    with pytest.raises(SplitError, match="distinct attribute vectors"):
        make_zsl_splits(handmade(attrs=shared), n_novel=6, n_splits=1, seed=0)
    with pytest.raises(SplitError, match="distinct attribute vectors"):  # only 6..9 unique
        make_zsl_splits(
            handmade(attrs=shared), n_novel=5, n_splits=1, seed=0, distinct_from_known=True
        )
    with pytest.raises(SplitError, match="distinct valid splits"):
        make_zsl_splits(ds, n_novel=1, n_splits=50, seed=0, max_draws=2000)  # at most 9 sets
    with pytest.raises(SplitError, match="trials"):
        make_zsl_splits(ds, n_novel=2, n_splits=1, seed=0, test_trials=5)
    with pytest.raises(SplitError, match="positive"):
        make_zsl_splits(ds, n_novel=0, n_splits=1, seed=0)


def test_simulated_dataset_splits_like_the_paper():
    ds = simulate_dataset(n_objects=30, trials_per_object=10, seed=0)
    splits = make_zsl_splits(ds, n_novel=6, n_splits=7, seed=0)
    assert len(splits) == 7
    for s in splits:
        assert len(s.known_test_idx) == 24 * 2 and len(s.known_train_idx) == 24 * 8
        assert len(s.novel_test_idx) == 6 * 9 and len(s.one_shot_idx) == 6
