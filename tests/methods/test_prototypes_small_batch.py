"""``prototypes``' small-batch path (``PrototypeSmallBatch``) against its general path, on
the simulator: the same answers for every batch size it takes, with and without novel
classes, after a promotion, and through an HNSW index."""

import copy

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.methods.prototype_search import PrototypeSearch
from app.methods.prototypes import PrototypeRecognizer

OBJECTS, TRIALS, HELD = 30, 7, 4  # 210 training samples: a full input profile
#: the kernel's exp, log and sums are libm's and run in candidate order: rounding apart
TOL = 1e-9


def _general(model: PrototypeRecognizer) -> PrototypeRecognizer:
    general = copy.copy(model)
    general.small_batch_max = 0
    return general


@pytest.fixture(scope="module")
def data():
    ds = simulate_dataset(OBJECTS + HELD, TRIALS, seed=3)
    known = ds.labels < OBJECTS
    train = ds.subset(np.flatnonzero(known)).select_classes(np.arange(OBJECTS))
    return train, ds.samples[known], ds.samples[~known]


@pytest.fixture(scope="module")
def model(data):
    return PrototypeRecognizer(seed=0).fit(data[0])


def _with_novel(model, train, held):
    """Two zero-shot classes and one learnt from a single sample of an unseen object."""
    rng = np.random.default_rng(0)
    taken = {tuple(v) for v in train.class_attributes.astype(int).tolist()}
    vectors = []
    while len(vectors) < 3:
        v = tuple((rng.random(train.n_attributes) < 0.3).astype(int).tolist())
        if sum(v) and v not in taken:
            taken.add(v)
            vectors.append(v)
    grown = model.add_novel_classes(["zsl-a", "zsl-b", "shot"], vectors)
    return grown.add_one_shot("shot", held[:1])


def _assert_same(fast, general, x):
    a = fast._all_scores(fast.validate_samples(x))
    b = general._all_scores(general.validate_samples(x))
    np.testing.assert_allclose(a[0], b[0], rtol=0, atol=TOL)  # novelty
    np.testing.assert_allclose(a[1], b[1], rtol=0, atol=TOL)  # known probabilities
    assert (a[2] is None) == (b[2] is None)
    if a[2] is not None:  # the novel part: the general code on the same inputs
        assert np.array_equal(a[2], b[2])
    ra, rb = fast.recognize_batch(x, top_k=3), general.recognize_batch(x, top_k=3)
    assert np.array_equal(ra.top_index, rb.top_index)
    assert np.array_equal(ra.is_novel, rb.is_novel)
    np.testing.assert_allclose(ra.top_probability, rb.top_probability, rtol=0, atol=TOL)


def test_the_small_batch_path_answers_as_the_general_path_one_sample_at_a_time(model, data):
    _, known, held = data
    general = _general(model)
    for x in (*known[::5], *held[::3]):
        _assert_same(model, general, x[None])
    assert model.__dict__.get("_few") is not None  # it was taken
    assert general.__dict__.get("_few") is None


@pytest.mark.parametrize("n", [2, 7, 32])
def test_every_batch_size_it_takes_answers_as_the_general_path(model, data, n):
    _, known, held = data
    x = np.concatenate([known, held])[np.random.default_rng(n).permutation(len(known))[:n]]
    _assert_same(model, _general(model), x)


def test_novel_classes_and_a_one_shot_class_answer_as_the_general_path(model, data):
    train, known, held = data
    grown = _with_novel(model, train, held)
    general = _general(grown)
    for x in (*known[::9], *held[1::4]):
        _assert_same(grown, general, x[None])
    _assert_same(grown, general, held[:5])


def test_a_promotion_rebuilds_the_scorer_and_the_model_before_answers_as_before(model, data):
    train, known, held = data
    one = held[:1]
    before = model.recognize_batch(one)
    scorer = model._few
    promoted = model.with_known_samples({"promoted": held[:TRIALS]})
    after = promoted.recognize_batch(one)
    assert promoted._few is not scorer
    assert promoted.registry.known_names[after.top_index[0, 0]] == "promoted"
    _assert_same(promoted, _general(promoted), one)
    _assert_same(promoted, _general(promoted), known[:3])
    again = model.recognize_batch(one)
    assert np.array_equal(again.top_index, before.top_index)
    assert np.array_equal(again.top_probability, before.top_probability)
    assert model._few is scorer


def test_an_hnsw_index_answers_as_the_general_path(data):
    train, known, held = data
    hnsw = PrototypeRecognizer(seed=0, exact_below=0).fit(train)
    assert not hnsw.search_.exact
    general = _general(hnsw)
    for x in (*known[::11], *held[::7]):
        _assert_same(hnsw, general, x[None])


def test_the_distances_to_every_prototype_are_the_reranking_distances_bit_for_bit():
    rng = np.random.default_rng(2)
    search = PrototypeSearch(rng.normal(size=(40, 16)).astype(np.float32))
    grown = search.with_points(rng.normal(size=(3, 16)).astype(np.float32))
    e = rng.normal(size=(5, 16)).astype(np.float32)
    for s in (search, grown):
        for rows in (e[:1], e):
            every = np.broadcast_to(np.arange(len(s)), (len(rows), len(s)))
            got = s.squared_to_all(rows)
            assert got.dtype == np.float32 and got.shape == (len(rows), len(s))
            assert np.array_equal(got.astype(np.float64), s.squared(rows, every))
    assert PrototypeSearch(e, exact_below=0).squared_to_all(e) is None


def test_samples_lacking_procedures_beside_complete_ones_answer_as_the_general_path(model, data):
    """A batch mixing complete samples (the small-batch path) with samples lacking some
    procedures (the marginal model's path, on both) answers as the general path does."""
    from app.data.procedures import keep_only

    _, known, held = data
    x = np.concatenate([known[:2], keep_only(known[2:4], model.procedures, [0, 2]), held[:1]])
    fast, general = model.recognize_batch(x), _general(model).recognize_batch(x)
    assert fast.procedures_used[:2].all() and not fast.procedures_used[2:4].all()
    assert np.array_equal(fast.top_index, general.top_index)
    assert np.array_equal(fast.procedures_used, general.procedures_used)
    assert np.array_equal(fast.next_procedure, general.next_procedure)
    np.testing.assert_allclose(fast.top_probability, general.top_probability, rtol=0, atol=TOL)
    np.testing.assert_allclose(fast.novelty_score, general.novelty_score, rtol=0, atol=TOL)
    lone = keep_only(held[1:2], model.procedures, [1])  # one partial sample alone
    a, b = model.recognize_batch(lone), _general(model).recognize_batch(lone)
    assert np.array_equal(a.top_probability, b.top_probability)
