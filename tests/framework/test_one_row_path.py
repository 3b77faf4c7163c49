"""A batch of one row takes ``TactileRecognizer._one_row``, not the general ``_rows``: its
answer must be the general path's bit for bit (indices, probabilities, novelty scores, novel
flags, dtypes and shapes, the order of ties, the padding past the classes there are), and so
must ``answers()`` and ``records()``. Checked on made-up scores full of ties, and on every
registered method fitted on the simulator, with and without novel classes (zero-shot, one-shot
and, for ``best``, learnt from samples alone)."""

from __future__ import annotations

import copy
from types import SimpleNamespace

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.framework.recognizer import (
    ClassRegistry,
    RecognitionBatch,
    TactileRecognizer,
    fuse_groups,
)
from app.framework.registry import METHODS, make_method
from tests.framework.test_no_attributes import without_attributes

FIELDS = ("top_index", "top_probability", "is_novel", "novelty_score")
TOP_KS = (0, 1, 2, 3, 5, 10, 200)  # 200: more than any model's classes (padding)

FAST = {
    "best": dict(n_estimators=40, tuning_rounds=1),
    "paper": dict(encoder_epochs=3, alg1_epochs=5, alg2_epochs=2, fc_z_epochs=5),
    "paper-fgmm": dict(encoder_epochs=3, alg1_epochs=5, alg2_epochs=2, fc_z_epochs=5),
    "extratrees": dict(n_estimators=30, attribute_estimators=20, n_jobs=1),
    "dap": dict(n_estimators=30, C=0.1, n_jobs=1),
    "eszsl": dict(n_estimators=30, n_jobs=1),
    "prototypes": {},
    # the model of the method its probe chose
    "auto": dict(probe_folds=1, params={"best": dict(n_estimators=40, tuning_rounds=1)}),
}


def assert_same(one: RecognitionBatch, ref: RecognitionBatch) -> None:
    """``one`` is ``ref`` bit for bit, and reads back alike."""
    assert type(one) is RecognitionBatch
    assert one.class_names == ref.class_names and type(one.class_names) is tuple
    assert one.n_known == ref.n_known
    for name in FIELDS:
        a, b = getattr(one, name), getattr(ref, name)
        assert a.dtype == b.dtype and a.shape == b.shape, name
        assert a.tobytes() == b.tobytes(), name  # bits, NaN padding included
    assert list(vars(one)) == list(RecognitionBatch.__dataclass_fields__)  # every field, no more
    # repr: exact for floats (shortest round trip), tells -0.0 from 0.0, and NaN equals NaN
    assert repr(one.answers()) == repr(ref.answers())
    assert repr(one.records()) == repr(ref.records())
    ids = {name: i for i, name in enumerate(ref.class_names)}
    assert repr(one.records(ids)) == repr(ref.records(ids))
    assert one.is_novel_class.tolist() == ref.is_novel_class.tolist()
    assert len(one) == 1 and len(one[0:1]) == 1


def healthy(model, batch: RecognitionBatch, x: np.ndarray, groups=None) -> RecognitionBatch:
    """``batch`` with the input health of its samples ``x``, as ``recognize_batch`` adds it
    after the ranking (``app.framework.input_health``)."""
    model._add_input_health(batch, model.validate_samples(x), groups)
    return batch


def stub(n_known: int, n_novel: int, threshold: float) -> SimpleNamespace:
    """What ``_one_row`` and ``_rows`` read of a recognizer: its classes and threshold."""
    registry = ClassRegistry(
        known_names=[f"known-{i}" for i in range(n_known)],
        novel_names=[f"novel-{i}" for i in range(n_novel)],
    )
    return SimpleNamespace(registry=registry, novelty_threshold=threshold)


def tied_rows(rng, n: int, k: int, dtype=np.float64) -> np.ndarray:
    """(n, k) probabilities with many ties: multiples of 1/8 (a forest of 8 trees), zeros,
    whole rows of one value, and a few -0.0 beside 0.0."""
    p = rng.integers(0, 3, (n, k)) * rng.integers(0, 4, (n, 1)) / 8.0
    p[::5] = 1.0 / k  # every class equal
    p[1::7] = 0.0
    p[2::9, ::2] = -0.0
    return p.astype(dtype)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("n_known, n_novel", [(1, 0), (2, 0), (7, 0), (60, 0), (60, 6), (3, 1)])
def test_one_row_ranks_ties_as_the_general_path(n_known, n_novel, dtype):
    rng = np.random.default_rng(n_known * 10 + n_novel)
    model = stub(n_known, n_novel, threshold=0.5)
    n = 120
    known_p = tied_rows(rng, n, n_known, dtype)
    novel_p = tied_rows(rng, n, n_novel, dtype) if n_novel else None
    # scores above, below and exactly at the threshold (not novel: the test is >), and NaN
    scores = rng.choice(np.array([0.25, 0.5, 0.75, np.nan, np.inf, -np.inf]), n).astype(dtype)
    for top_k in TOP_KS:
        general = TactileRecognizer._rows(model, scores, known_p, novel_p, top_k)
        for i in range(n):
            rows = slice(i, i + 1)
            row = (scores[rows], known_p[rows], None if novel_p is None else novel_p[rows])
            one = TactileRecognizer._one_row(model, *row, top_k)
            alone = TactileRecognizer._rows(model, *row, top_k)
            assert_same(one, alone)
            if dtype is np.float64:
                assert_same(one, general[rows])
            else:  # the general path's mixed batches rank into float64 (one row never mixes)
                promoted = RecognitionBatch(**vars(one))
                object.__setattr__(
                    promoted,
                    "top_probability",
                    one.top_probability.astype(general.top_probability.dtype),
                )
                assert_same(promoted, general[rows])


def test_one_row_takes_arrays_of_any_layout():
    """A probability row that is a strided view (of a Fortran-ordered or wider array) gives
    the bits of a contiguous one."""
    rng = np.random.default_rng(1)
    model = stub(9, 4, threshold=0.0)
    wide = np.asfortranarray(tied_rows(rng, 3, 26))
    for score in (-1.0, 1.0):
        scores = np.array([score])
        known_p, novel_p = wide[1:2, ::2][:, :9], wide[2:3, 1::3][:, :4]
        assert not known_p.flags.c_contiguous or not novel_p.flags.c_contiguous
        for top_k in TOP_KS:
            assert_same(
                TactileRecognizer._one_row(model, scores, known_p, novel_p, top_k),
                TactileRecognizer._rows(model, scores, known_p.copy(), novel_p.copy(), top_k),
            )


def test_batch_dispatches_one_row_and_keeps_the_general_path_for_more():
    model = stub(5, 2, threshold=0.5)
    rng = np.random.default_rng(2)
    scores, known_p, novel_p = rng.random(4), tied_rows(rng, 4, 5), tied_rows(rng, 4, 2)
    calls = []

    class Spy(SimpleNamespace):
        def _one_row(self, *args):
            calls.append("one")
            return TactileRecognizer._one_row(self, *args)

        def _rows(self, *args):
            calls.append("rows")
            return TactileRecognizer._rows(self, *args)

    spy = Spy(**vars(model))
    TactileRecognizer._batch(spy, scores[:1], known_p[:1], novel_p[:1], 3)
    TactileRecognizer._batch(spy, scores, known_p, novel_p, 3)
    assert calls == ["one", "rows"]


# ----------------------------------------------------------- every registered method


@pytest.fixture(scope="module")
def data():
    ds = simulate_dataset(n_objects=14, trials_per_object=5, seed=7)
    known = ds.select_classes(np.arange(10))
    trial_no = np.arange(len(known)) % 5  # samples come by object, then trial
    return {
        "train": known.subset(trial_no < 4),
        "test": known.subset(trial_no == 4),
        "novel": ds.select_classes(np.arange(10, 14)),
    }


def enrolled(model, novel):
    """``model`` with the novel objects enrolled zero-shot and half of them given one-shot
    samples (where the method takes them)."""
    model = model.add_novel_classes(
        novel.class_names, novel.class_attributes, allow_known_vectors=True
    )
    for c, name in enumerate(novel.class_names[:2]):
        try:
            model = model.add_one_shot(name, novel.samples[novel.labels == c][:1])
        except Exception as err:  # noqa: BLE001 (a method without one-shot learning)
            pytest.skip(f"{model.method}: no one-shot samples ({err})")
    return model


@pytest.fixture(scope="module", params=sorted(METHODS))
def models(request, data):
    base = make_method(request.param, **FAST[request.param]).fit(data["train"])
    return base, enrolled(base, data["novel"])


def samples_of(data) -> np.ndarray:
    """Known test samples, novel objects' samples, and a far-off sample (novel for sure)."""
    x = np.concatenate([data["test"].samples, data["novel"].samples[::3]])
    return np.concatenate([x, x[:1] * 50.0])


def check_model(model, x: np.ndarray) -> None:
    """Each sample's 1-row answer is the general path's on the same scores; and the scores
    of a 1-sample call route through ``_one_row`` unchanged. The threshold is set to the
    middle sample's score, so that both classifiers answer (and one score equals it)."""
    model = copy.copy(model)
    every = np.concatenate([model.novelty_score(x[i : i + 1]) for i in range(len(x))])
    model.novelty_threshold = float(np.sort(every)[len(every) // 2])
    routed = {False: 0, True: 0}
    for i in range(len(x)):
        one = x[i : i + 1]
        scores, known_p, novel_p = model._all_scores(model.validate_samples(one))
        routed[bool(scores[0] > model.novelty_threshold)] += 1
        for top_k in TOP_KS:
            ref = model._complete(TactileRecognizer._rows(model, scores, known_p, novel_p, top_k))
            ref = healthy(model, ref, one)
            assert_same(model.recognize_batch(one, top_k), ref)
            assert_same(model.recognize_batch(one[0], top_k), ref)  # no batch axis
        ref = model._complete(TactileRecognizer._rows(model, scores, known_p, novel_p, 3))
        ref = healthy(model, ref, one)
        assert repr(model.recognize(one)) == repr(ref.answers())
        # two samples fused as one group: one row too
        pair = x[[i, (i + 1) % len(x)]]
        fused = fuse_groups(np.zeros(2, np.int64), *model._all_scores(model.validate_samples(pair)))
        assert_same(
            model.recognize_batch(pair, 3, groups=[0, 0]),
            healthy(
                model,
                model._complete(TactileRecognizer._rows(model, *fused, 3)),
                pair,
                np.zeros(2, np.int64),
            ),
        )
    assert routed[False] and routed[True], routed  # both classifiers answered some sample


def test_every_method_one_row_is_the_general_path(models, data):
    base, with_novel = models
    x = samples_of(data)
    check_model(base, x)
    check_model(with_novel, x)


def general_path(model, one: np.ndarray, top_k: int) -> RecognitionBatch:
    """``best``'s 1-sample answer all the general way: its general scorer
    (``small_batch_max = 0``), then the general ranking (``_rows``)."""
    general = copy.copy(model)
    general.small_batch_max = 0
    batch = general._complete(
        TactileRecognizer._rows(general, *general._all_scores(general.validate_samples(one)), top_k)
    )
    return healthy(general, batch, one)


def test_best_one_sample_is_the_general_path_bit_for_bit(data):
    """``best``'s 1-sample call (small-batch scorer, then ``_one_row``) against the general
    scorer and ranking, with and without novel classes (zero-shot and one-shot)."""
    base = make_method("best", **FAST["best"]).fit(data["train"])
    x = samples_of(data)
    for model in (base, enrolled(base, data["novel"])):
        for top_k in TOP_KS:
            for i in range(len(x)):
                one = x[i : i + 1]
                assert_same(model.recognize_batch(one, top_k), general_path(model, one, top_k))


def test_best_classes_from_samples_alone_one_row(data):
    """``best`` without attributes: novel classes learnt from samples alone, then one more
    one-shot sample; one sample at a time against the general path."""
    model = make_method("best", **FAST["best"]).fit(without_attributes(data["train"]))
    novel = data["novel"]
    model = model.add_novel_classes_from_samples(
        {name: novel.samples[novel.labels == c][:1] for c, name in enumerate(novel.class_names)}
    )
    model = model.add_one_shot(novel.class_names[0], novel.samples[novel.labels == 0][1:2])
    x = samples_of(data)
    check_model(model, x)
    for top_k in TOP_KS:
        for i in range(len(x)):
            one = x[i : i + 1]
            assert_same(model.recognize_batch(one, top_k), general_path(model, one, top_k))


def test_answers_of_one_model_share_one_tuple_of_class_names():
    """``joined_names``: the known and novel names joined once per pair of name lists, so
    that an answer does not visit every class (the service's labels check ``is`` first); a
    list that grew, or other lists, get a tuple of their own."""
    from app.framework.results import joined_names

    known, novel = [f"k{i}" for i in range(50)], ["n0"]
    first = joined_names(known, novel)
    assert first == (*known, *novel) and joined_names(known, novel) is first
    novel.append("n1")  # never done by a registry, but a stale tuple must not come back
    assert joined_names(known, novel) == (*known, "n0", "n1")
    other = list(known)
    assert joined_names(other, []) == tuple(known) and joined_names(other, []) is not first
    reg = ClassRegistry(known_names=known, novel_names=novel)
    model = SimpleNamespace(registry=reg, novelty_threshold=0.5)
    scores, p = np.array([0.1]), np.full((1, 50), 0.02)
    a = TactileRecognizer._one_row(model, scores, p, None, 3)
    b = TactileRecognizer._rows(model, np.array([0.1, 0.2]), np.r_[p, p], None, 3)
    assert a.class_names is b.class_names is joined_names(known, novel)
