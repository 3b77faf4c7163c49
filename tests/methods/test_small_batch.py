"""``best``'s small-batch path (``app.methods.small_batch``) gives the general path's answers
bit for bit: every output of ``recognize_batch`` and ``attribute_proba``, for single samples,
small batches and a large one, on models with and without novel classes, one-shot samples,
the semantic autoencoder, subspace or exact distances, a neighbour index, and attributes;
and its sums along a row add in numpy's order."""

from __future__ import annotations

import ast
import copy
import dataclasses
import inspect
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.framework.recognizer import RecognitionBatch
from app.framework.registry import make_method
from app.methods import small_batch
from app.methods.known import KnownModel
from app.methods.small_batch import ScoringConstants, _row_sum
from tests.framework.test_no_attributes import without_attributes

FIELDS = ("top_index", "top_probability", "is_novel", "novelty_score")
SIZES = (1, 2, 7, 32)  # 32: BestRecognizer.small_batch_max
LARGE = 150


def general(model):
    """``model`` forced onto the general path (the reference)."""
    out = copy.copy(model)
    out.small_batch_max = 0
    return out


def small(model, most: int = 10_000):
    """``model`` taking the small-batch path up to ``most`` samples."""
    out = copy.copy(model)
    out.small_batch_max = most
    return out


def reference_batch(model, scores, known_p, novel_p, top_k) -> RecognitionBatch:
    """``TactileRecognizer._batch`` as it was before the one-classifier shortcut (commit
    1ab2f22): every classifier's rows ranked from a masked copy (by a stable sort: equal
    probabilities rank the lower class index first)."""
    novel = scores > model.novelty_threshold
    reg = model.registry
    n, k, n_known = len(scores), max(1, top_k), len(reg.known_names)
    use_novel = novel & (novel_p is not None)
    top_index = np.full((n, k), -1, np.int64)
    top_p = np.full((n, k), np.nan)
    for probs, offset, rows in ((known_p, 0, ~use_novel), (novel_p, n_known, use_novel)):
        if not rows.any():
            continue
        p = probs[rows]
        order = np.argsort(-p, axis=1, kind="stable")[:, :k]
        top_index[rows, : order.shape[1]] = order + offset
        top_p[rows, : order.shape[1]] = np.take_along_axis(p, order, axis=1)
    return RecognitionBatch(
        tuple(reg.all_names), n_known, top_index, top_p, novel, scores.astype(np.float64)
    )


def assert_same_bits(a: RecognitionBatch, b: RecognitionBatch) -> None:
    for field in FIELDS:
        x, y = getattr(a, field), getattr(b, field)
        assert x.dtype == y.dtype and x.shape == y.shape, field
        assert x.tobytes() == y.tobytes(), field


@pytest.fixture(scope="module")
def data():
    """16 simulated objects: 12 known, 4 held out as novel (distinct attribute vectors)."""
    ds = simulate_dataset(n_objects=16, trials_per_object=5, seed=3)
    _, first = np.unique(ds.class_attributes, axis=0, return_index=True)
    novel = np.sort(first)[-4:]
    known = np.setdiff1d(np.arange(ds.n_classes), novel)
    return ds, ds.select_classes(known), novel


def queries(ds, seed: int = 0) -> np.ndarray:
    """Samples of every object, some far from any (scaled and noisy): both routes taken."""
    rng = np.random.default_rng(seed)
    x = ds.samples[rng.permutation(len(ds))[:LARGE]].copy()
    x[::3] *= rng.uniform(0.3, 3.0, (len(x[::3]), 1, 1)).astype(np.float32)
    x[1::4] += rng.normal(0, 0.5, x[1::4].shape).astype(np.float32)
    return x


def grown(model, ds, novel, shots: int):
    names = [f"new-{i}" for i in range(len(novel))]
    model = model.add_novel_classes(names, ds.class_attributes[novel])
    for name, c in list(zip(names, novel, strict=True))[:shots]:
        model = model.add_one_shot(name, ds.samples[ds.labels == c][:1])
    return model


@pytest.fixture(
    scope="module",
    params=[
        pytest.param(dict(distance_components=8), id="subspace"),
        pytest.param(dict(distance_components=0, sae_lambda=0.0), id="exact-no-sae"),
        # 60 training samples: the nearest ones found through the HNSW index
        pytest.param(dict(distance_components=8, approximate_above=40), id="indexed"),
    ],
)
def models(request, data):
    ds, train, novel = data
    base = make_method("best", n_estimators=30, tuning_rounds=1, seed=1, **request.param).fit(train)
    return {
        "base": base,
        "zero-shot": grown(base, ds, novel, shots=0),
        "one-shot": grown(base, ds, novel, shots=2),
        "all-shot": grown(base, ds, novel, shots=len(novel)),
        "graded": graded(base, ds, novel),
    }


def graded(model, ds, novel):
    """Novel classes described by graded values and values not known, one with a shot."""
    vectors = ds.class_attributes[novel].copy()
    vectors[0, :3] = np.nan
    vectors[1, 0] = 0.5
    vectors[2, -1] = 0.3
    names = [f"new-{i}" for i in range(len(novel))]
    model = model.add_novel_classes(names, vectors)
    return model.add_one_shot(names[3], ds.samples[ds.labels == novel[3]][:1])


@pytest.mark.parametrize("which", ["base", "zero-shot", "one-shot", "all-shot", "graded"])
def test_small_batches_match_the_general_path(models, data, which):
    model, x = models[which], queries(data[0])
    ref, fast = general(model), small(model, most=max(SIZES))
    for n in SIZES:
        for start in range(0, 3 * n, n):
            for top_k in (1, 3, 40):  # 40: more than the classes, padded
                batch = x[start : start + n]
                assert_same_bits(
                    fast.recognize_batch(batch, top_k), ref.recognize_batch(batch, top_k)
                )
                assert fast.attribute_proba(batch).tobytes() == ref.attribute_proba(batch).tobytes()


@pytest.mark.parametrize("which", ["base", "one-shot"])
def test_a_large_batch_on_the_small_path_matches_too(models, data, which):
    model, x = models[which], queries(data[0], seed=1)
    answer = small(model).recognize_batch(x, 5)
    assert answer.is_novel.any() and not answer.is_novel.all()  # both routes in one batch
    assert_same_bits(answer, general(model).recognize_batch(x, 5))
    groups = np.arange(len(x)) // 2
    assert_same_bits(
        small(model).recognize_batch(x, 3, groups=groups),
        general(model).recognize_batch(x, 3, groups=groups),
    )


@pytest.mark.parametrize("which", ["base", "zero-shot", "one-shot"])
def test_ranking_matches_the_masked_copies_it_replaced(models, data, which):
    model, x = models[which], queries(data[0], seed=2)
    for n in (*SIZES, LARGE):
        scores, known_p, novel_p = general(model)._all_scores(x[:n])
        for top_k in (1, 3, 40):
            assert_same_bits(
                model._batch(scores, known_p, novel_p, top_k),
                reference_batch(model, scores, known_p, novel_p, top_k),
            )


def test_default_threshold_sends_one_sample_down_the_small_path(models, data):
    model = models["one-shot"]
    assert 1 <= model.small_batch_max
    x = queries(data[0])[:1]
    assert_same_bits(model.recognize_batch(x), general(model).recognize_batch(x))
    assert model._small_batch is not None
    # enrolment builds the next model's constants afresh, and leaves this one's alone
    bigger = model.add_one_shot("new-3", x)
    assert bigger._small_batch is None
    assert_same_bits(bigger.recognize_batch(x), general(bigger).recognize_batch(x))
    assert_same_bits(model.recognize_batch(x), general(model).recognize_batch(x))


def test_an_indexed_model_takes_the_small_path_through_its_index(models, data):
    """With a neighbour index the scorer searches it (exact products with every reference
    sample would cost milliseconds at 30,000 objects); without one it keeps the products."""
    model = models["one-shot"]
    indexed = model.known_.cues_model.distances.index is not None
    constants = ScoringConstants.of(model)
    assert (constants.indexed is not None) == indexed
    assert (constants.ref_t.size == 0) == indexed
    x = queries(data[0], seed=8)[:1]
    assert_same_bits(small(model).recognize_batch(x), general(model).recognize_batch(x))


def test_samples_that_reach_one_class_alone_match_too(models, data):
    """The kernel skips the classes no tree reached; where every tree reached one class, the
    second largest probability is one of those zeros, as the general path finds it."""
    model, x = models["one-shot"], queries(data[0], seed=9)
    _, known_p, _ = general(model)._all_scores(x)
    one = np.flatnonzero((known_p > 0).sum(axis=1) == 1)
    several = np.flatnonzero((known_p > 0).sum(axis=1) > 1)
    assert len(one) and len(several)
    for rows in (one[:5], several[:5]):
        for i in rows:
            assert_same_bits(
                small(model).recognize_batch(x[i : i + 1], 3),
                general(model).recognize_batch(x[i : i + 1], 3),
            )


def test_the_scorer_reads_only_its_frozen_constants(models):
    """The scorer's contract with ``best``: a frozen ``ScoringConstants`` built through the
    parts' public methods; no private field of another object is read in the module."""
    model = models["one-shot"]
    constants = ScoringConstants.of(model)
    with pytest.raises(dataclasses.FrozenInstanceError):
        constants.settings = None  # type: ignore[misc]
    assert constants.novel is not None
    with pytest.raises(dataclasses.FrozenInstanceError):
        constants.novel.n_novel = 0  # type: ignore[misc]
    tree = ast.parse(inspect.getsource(small_batch))
    private = [
        ast.unparse(node)
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute)
        and node.attr.startswith("_")
        and not (isinstance(node.value, ast.Name) and node.value.id == "self")
    ]
    assert private == []


def test_without_attributes_classes_from_samples_match(data):
    ds, train, novel = data
    bare = without_attributes(train)
    model = make_method("best", n_estimators=30, tuning_rounds=1).fit(bare)
    x = queries(ds, seed=3)
    for m in (
        model,
        model.add_novel_classes_from_samples(
            {f"new-{i}": ds.samples[ds.labels == c][:2] for i, c in enumerate(novel)}
        ),
    ):
        for n in (*SIZES, LARGE):
            assert_same_bits(small(m).recognize_batch(x[:n]), general(m).recognize_batch(x[:n]))


def test_a_weighted_entropy_cue_is_computed_as_the_general_path_does(models, data):
    """``best`` weighs the entropy cue 0, so the small path skips it; with a weight it is
    computed, with the same bits."""
    model = copy.deepcopy(models["one-shot"])  # shares the fitted known part: give it its own
    weights = model.known_.weights + np.r_[0.0, 0.3, 0.0, 0.0, 0.0, 0.0]
    model.known_ = KnownModel(model.known_.cues_model, weights)
    model._small_batch = None
    x, fast = queries(data[0], seed=4), small(model)
    for n in SIZES:
        assert_same_bits(fast.recognize_batch(x[:n]), general(model).recognize_batch(x[:n]))
    assert fast._small_batch.constants.entropy_used


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_row_sums_add_in_numpys_order(dtype):
    """The kernels' ``_row_sum`` gives ``np.add.reduce``'s bits along a row: numpy's pairwise
    summation, in one block up to 128 elements and in halves above (lengths around every
    boundary, rows of mixed magnitudes so that the order shows in the last bits)."""
    rng = np.random.default_rng(5)
    zero = dtype(0.0)
    lengths = [*range(0, 140), 255, 256, 257, 383, 512, 600, 959, 960, 961, 2049, 10_000]
    for n in lengths:
        m = (rng.standard_normal((3, n)) * rng.uniform(0.1, 1e3, (3, 1))).astype(dtype)
        m[:, ::5] *= dtype(1e-4)
        want = np.add.reduce(m, axis=1)
        got = np.array([_row_sum(row, zero) for row in m], dtype)
        assert got.tobytes() == want.tobytes(), n


def test_threads_keep_their_own_one_sample_arrays(models, data):
    """One sample's intermediate arrays are kept per thread: threads scoring different
    samples at once get each sample's own answer."""
    model, x = small(models["one-shot"]), queries(data[0], seed=5)[:8]
    want = [general(model).recognize_batch(x[i : i + 1]) for i in range(len(x))]
    model.recognize_batch(x[:1])  # build the scorer before the threads start

    def answers(i: int) -> list[RecognitionBatch]:
        return [model.recognize_batch(x[i : i + 1]) for _ in range(50)]

    with ThreadPoolExecutor(4) as pool:
        for i, got in enumerate(pool.map(answers, range(len(x)))):
            for answer in got:
                assert_same_bits(answer, want[i])


def test_a_copied_model_leaves_the_scorer_behind_and_scores_alike(models, data):
    """A deep copy (as enrolment copies the model) leaves the scorer, a cache holding the
    reference samples' index, behind: the copy builds its own on its first small batch
    and gives the same bits."""
    model, x = small(models["zero-shot"]), queries(data[0], seed=6)[:3]
    first = model.recognize_batch(x[:1])
    assert model._small_batch is not None
    twin = copy.deepcopy(model)
    assert getattr(twin, "_small_batch", None) is None
    for n in (1, 3):
        assert_same_bits(twin.recognize_batch(x[:n]), model.recognize_batch(x[:n]))
    assert_same_bits(twin.recognize_batch(x[:1]), first)
    assert twin._small_batch is not None and twin._small_batch is not model._small_batch
    assert model._small_batch is not None  # the original keeps its own


def test_a_scaler_without_log_compression_matches(models, data):
    """The kernels scale raw inputs when the scaler does not log-compress (``best`` always
    does; the scaler allows it)."""
    model = copy.deepcopy(models["one-shot"])  # shares the fitted known part: give it its own
    cues = copy.deepcopy(model.known_.cues_model)
    cues.scaler.log_compress = False
    model.known_ = KnownModel(cues, model.known_.weights)
    model._small_batch = None
    x, fast = queries(data[0], seed=7), small(model)
    for n in SIZES:
        assert_same_bits(fast.recognize_batch(x[:n]), general(model).recognize_batch(x[:n]))
    assert not fast._small_batch.constants.log_compress
