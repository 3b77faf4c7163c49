"""The ``best`` method on small simulated data: the full protocol beats chance on novel
classes, enrolment works and is fast, bundles round-trip exactly, bad input is refused."""

from __future__ import annotations

import time

import numpy as np
import pytest

from app.data.dataset import DatasetError, TactileDataset
from app.data.simulator import simulate_dataset
from app.evaluation.protocol import FIGURES
from app.framework import bundle
from app.framework.errors import (
    AttributeVectorError,
    BundleError,
    DuplicateClassError,
    FrameworkError,
    InputShapeError,
    NonFiniteInputError,
    NotFittedError,
    UnknownClassError,
)
from app.framework.registry import make_method
from app.methods.attributes import (
    LinearAttributeModel,
    cosine_scores,
    dap_log_scores,
    semantic_autoencoder,
)
from app.methods.best import BestRecognizer
from tests.simulated_protocol import N_NOVEL, small_protocol

FAST = {
    "n_estimators": 40,
    "tuning_rounds": 2,
    "distance_components": 8,
}  # 8 < rank: subspace distances


@pytest.fixture(scope="module")
def protocol_results():
    return small_protocol(["best"], 2, {"best": FAST})


def test_full_protocol_beats_chance_on_novel_classes(protocol_results):
    mean = protocol_results["methods"]["best"]["mean"]
    chance = 1 / N_NOVEL
    assert mean["zsl"] >= chance + 0.15, mean
    assert mean["osl"] >= chance + 0.4, mean
    assert mean["gzsl_unseen"] >= chance, mean
    assert mean["known_acc"] >= 0.85, mean
    assert mean["nd_auroc"] >= 0.8, mean
    for f in FIGURES:
        assert 0.0 <= mean[f] <= 1.0, f


@pytest.fixture(scope="module")
def data():
    """16 simulated objects: 12 known (4 training trials, 1 test trial), 4 novel."""
    ds = simulate_dataset(n_objects=16, trials_per_object=5, seed=3)
    _, first = np.unique(ds.class_attributes, axis=0, return_index=True)
    novel = np.sort(first)[-4:]  # distinct vectors
    known = np.setdiff1d(np.arange(ds.n_classes), novel)
    is_test = (ds.trials % 5) == 0
    train = ds.subset(~is_test).select_classes(known)
    return ds, train, known, novel, is_test


@pytest.fixture(scope="module")
def fitted(data):
    _, train, *_ = data
    return make_method("best", **FAST).fit(train)


@pytest.fixture(scope="module")
def enrolled(fitted, data):
    ds, _, _, novel, _ = data
    names = [f"new-{i}" for i in range(len(novel))]
    return fitted.add_novel_classes(names, ds.class_attributes[novel]), names


def test_interface_shapes_and_scores(fitted, data):
    ds, train, known, _, is_test = data
    x = ds.samples[is_test & np.isin(ds.labels, known)]
    p = fitted.known_proba(x)
    assert p.shape == (len(x), train.n_classes)
    np.testing.assert_allclose(p.sum(axis=1), 1.0)
    s = fitted.novelty_score(x)
    assert s.shape == (len(x),) and np.isfinite(s).all()
    assert np.isfinite(fitted.novelty_threshold)
    tuning = fitted.novelty_tuning
    assert 0 <= tuning.known_kept_at_threshold <= 1 and 0 <= tuning.val_novel_at_threshold <= 1
    assert set(fitted.metrics["timings"]) >= {"novelty_tuning_s", "known_model_s", "total_s"}
    answers = fitted.recognize(x[:3], top_k=2)
    assert all(a.kind == "known" and a.class_name in train.class_names for a in answers)


def test_enrolment_is_new_model_and_fast(fitted, enrolled, data):
    ds, _, _, novel, _ = data
    model, names = enrolled
    assert fitted.registry.novel_names == [] and model.registry.novel_names == names
    t = time.perf_counter()
    again = fitted.add_novel_classes(["extra"], ds.class_attributes[novel[:1]])
    assert time.perf_counter() - t < 1.0
    x = ds.samples[ds.labels == novel[0]]
    p = again.novel_proba(x)
    assert p.shape == (len(x), 1)
    t = time.perf_counter()
    shot = model.add_one_shot(names[0], x[:1])
    assert time.perf_counter() - t < 2.0
    assert model.registry.novel_samples == {} and len(shot.registry.novel_samples[names[0]]) == 1
    p = shot.novel_proba(ds.samples[np.isin(ds.labels, novel)])
    np.testing.assert_allclose(p.sum(axis=1), 1.0)
    answers = shot.recognize(x[:2])
    assert all(a.class_name in shot.registry.all_names for a in answers)


def test_one_shot_samples_help(enrolled, data):
    ds, _, _, novel, is_test = data
    model, names = enrolled
    for name, c in zip(names, novel, strict=True):
        shot_idx = np.flatnonzero((ds.labels == c) & is_test)[0]
        model = model.add_one_shot(name, ds.samples[shot_idx])
    test = np.isin(ds.labels, novel) & ~is_test
    truth = np.searchsorted(novel, ds.labels[test])
    acc = np.mean(model.novel_proba(ds.samples[test]).argmax(axis=1) == truth)
    assert acc >= 0.7, acc  # chance is 0.25


def test_bundle_round_trip_gives_identical_predictions(enrolled, data, tmp_path):
    ds, *_ = data
    model, names = enrolled
    model = model.add_one_shot(names[1], ds.samples[:1])
    path = tmp_path / "best.bundle"
    bundle.save(model, path)
    again = bundle.load(path)
    assert isinstance(again, BestRecognizer)
    assert again.known_.cues_model.distances.basis.shape[1] == FAST["distance_components"]
    assert again.registry.all_names == model.registry.all_names
    x = ds.samples
    assert np.array_equal(again.known_proba(x), model.known_proba(x))
    assert np.array_equal(again.novel_proba(x), model.novel_proba(x))
    assert np.array_equal(again.novelty_score(x), model.novelty_score(x))
    assert again.novelty_threshold == model.novelty_threshold
    assert [a.class_name for a in again.recognize(x)] == [a.class_name for a in model.recognize(x)]
    # and it keeps growing after loading
    grown = again.add_one_shot(names[2], x[1:2])
    assert grown.novel_proba(x).shape == (len(x), len(names))


def test_corrupt_bundle_is_refused(enrolled):
    model, _ = enrolled
    data = bundle.to_bytes(model)
    with pytest.raises(BundleError):
        bundle.from_bytes(data[: len(data) // 2])
    meta, arrays = model.get_state()
    fresh = BestRecognizer()
    fresh.input_shape, fresh.registry = model.input_shape, model.registry
    with pytest.raises((KeyError, ValueError)):
        fresh.set_state(
            meta, {k: v for k, v in arrays.items() if not k.startswith("known/forest/")}
        )


def test_bad_input_raises_framework_errors(fitted, enrolled, data):
    ds, train, *_ = data
    model, names = enrolled
    x = ds.samples[:2]
    with pytest.raises(InputShapeError):
        fitted.known_proba(x.reshape(2, -1))
    with pytest.raises(InputShapeError):
        fitted.recognize(np.zeros((0,) + train.input_shape, np.float32))
    bad = x.copy()
    bad[1, 0, 0] = np.nan
    with pytest.raises(NonFiniteInputError):
        fitted.novelty_score(bad)
    with pytest.raises(AttributeVectorError):
        fitted.add_novel_classes(["z"], [[1, 0]])
    with pytest.raises(AttributeVectorError):
        fitted.add_novel_classes(["z"], [np.full(train.n_attributes, 1.5)])  # beyond [0, 1]
    with pytest.raises(AttributeVectorError):
        fitted.add_novel_classes(["z"], [np.full(train.n_attributes, np.nan)])  # nothing known
    with pytest.raises(DuplicateClassError):
        fitted.add_novel_classes([train.class_names[0] + "-twin"], train.class_attributes[:1])
    with pytest.raises(DuplicateClassError):
        model.add_novel_classes([names[0]], np.eye(train.n_attributes)[:1])
    with pytest.raises(UnknownClassError):
        model.add_one_shot("nobody", x[:1])
    with pytest.raises(UnknownClassError):
        model.add_one_shot(train.class_names[0], x[:1])
    with pytest.raises(UnknownClassError):
        fitted.novel_proba(x)
    with pytest.raises(FrameworkError, match="enrolment options"):
        fitted.add_novel_classes(["z"], np.eye(train.n_attributes)[:1], synthesis="genf")
    with pytest.raises(NotFittedError):
        BestRecognizer().known_proba(x)


@pytest.mark.parametrize(
    "params",
    [
        {"n_estimators": 0},
        {"attribute_C": -1.0},
        {"dap_clip": 0.7},
        {"shot_temperature": 0},
        {"max_features": "all"},
        {"tuning_rounds": 0},
        {"novelty_val_fraction": 1.5},
        {"knn_weight": -1},
        {"distance_components": -1},
        {"distance_components": 2.5},
        {"sae_lambda": -1},
        {"sae_temperature": float("nan")},
        {"sae_lambda": True},
    ],
)
def test_bad_hyper_parameters(params, data):
    model = BestRecognizer(**params)  # the constructor only stores its arguments
    with pytest.raises(FrameworkError, match=f"^{next(iter(params))} must "):
        model.fit(data[1])  # fit checks them before any work
    assert model.input_shape is None


@pytest.mark.parametrize(
    "params, message",
    [
        ({"n_estimators": 0}, "n_estimators must be a positive integer, got 0"),
        ({"dap_clip": 0.7}, r"dap_clip must lie in \(0, 0.5\), got 0.7"),
        ({"max_features": "all"}, "max_features must be 'sqrt', 'log2' or a positive number"),
        ({"distance_components": 2.5}, r"distance_components must be a non-negative integer \(0"),
        ({"sae_lambda": True}, "sae_lambda must be a non-negative number, got True"),
        ({"procedure_estimators": 0}, "procedure_estimators must be None or a positive integer"),
    ],
)
def test_hyper_parameter_errors_name_the_parameter_and_the_value(params, message, data):
    with pytest.raises(FrameworkError, match=message):
        BestRecognizer(**params).fit(data[1])


def test_datasets_it_cannot_learn_from_are_refused():
    one_trial = TactileDataset(
        samples=np.random.default_rng(0).normal(size=(6, 4)),
        labels=np.arange(6),
        trials=np.arange(6),
        class_attributes=np.eye(6, 3),
        attribute_names=("a", "b", "c"),
        class_names=tuple("uvwxyz"),
    )
    with pytest.raises(DatasetError, match="trials"):
        BestRecognizer(**FAST).fit(one_trial)
    single = one_trial.select_classes([0])
    with pytest.raises(DatasetError, match="2 known classes"):
        BestRecognizer(**FAST).fit(single)


def test_dap_and_attribute_model():
    rng = np.random.default_rng(0)
    z = rng.normal(size=(80, 5))
    t = np.c_[z[:, 0] > 0, z[:, 1] > 0, np.ones(80)]  # the last attribute is constant
    model = LinearAttributeModel.fit(z, t, C=1.0)
    p = model.predict_proba(z)
    assert np.all(p[:, 2] == 1.0)
    assert np.mean((p[:, 0] > 0.5) == t[:, 0]) > 0.9
    classes = np.array([[1, 0, 1], [0, 1, 1]])
    s = dap_log_scores(np.array([[0.9, 0.1, 1.0]]), classes, np.array([0.5, 0.5, 1.0]), 0.02)
    assert s.argmax() == 0
    again = LinearAttributeModel.from_state(model.get_state())
    assert np.array_equal(again.predict_proba(z), p)


def test_semantic_autoencoder_maps_samples_to_their_attributes():
    rng = np.random.default_rng(0)
    classes = rng.integers(0, 2, size=(8, 6)).astype(float)
    mixing = rng.normal(size=(6, 20))
    y = np.repeat(np.arange(8), 10)
    z = classes[y] @ mixing + 0.05 * rng.normal(size=(80, 20))  # features made from attributes
    w = semantic_autoencoder(z, classes[y], lam=10.0)
    assert w.shape == (6, 20)
    assert np.mean((z @ w.T > 0.5) == classes[y]) > 0.95  # W z recovers the attributes
    constant = np.c_[classes[y], np.ones(80)]  # an attribute no class lacks: still solvable
    assert np.isfinite(semantic_autoencoder(z, constant, lam=10.0)).all()


def test_the_autoencoder_adds_to_dap_and_old_bundles_keep_dap_alone(enrolled, data):
    ds, *_ = data
    model, names = enrolled
    x = ds.samples
    assert model.sae_ is not None and model.sae_.shape == (
        ds.n_attributes,
        int(np.prod(ds.input_shape)),
    )
    z = model.known_.cues_model.scaled(x.reshape(len(x), -1))
    dap = dap_log_scores(
        model.attributes_.predict_proba(z),
        model.registry.novel_attributes,
        model.prior_,
        model.dap_clip,
    )
    both = dap + model.sae_temperature * cosine_scores(
        z, model.sae_, model.registry.novel_attributes
    )
    expected = np.exp(both - both.max(1, keepdims=True))
    assert np.allclose(model.novel_proba(x), expected / expected.sum(1, keepdims=True), atol=1e-6)

    meta, arrays = model.get_state()  # a bundle written before the autoencoder existed
    del meta["params"]["sae_lambda"], meta["params"]["sae_temperature"], arrays["sae"]
    old = BestRecognizer()
    old.input_shape, old.registry = model.input_shape, model.registry
    old.set_state(meta, arrays)
    assert old.sae_ is None and old.sae_lambda == 0
    plain = np.exp(dap - dap.max(1, keepdims=True))
    assert np.allclose(old.novel_proba(x), plain / plain.sum(1, keepdims=True), atol=1e-6)


def test_distance_offsets_are_blockwise_exact_and_finite():
    from app.methods.known import ReferenceDistances, _offsets

    rng = np.random.default_rng(0)
    ref = ReferenceDistances(rng.normal(size=(40, 5)))
    y = np.repeat(np.arange(8), 5)
    trials = np.arange(40)
    trials[35:] = 35  # class 7: one trial only, so it has no own-class spacing of its own
    whole = _offsets(ref, y, trials, 8)
    assert np.allclose(whole, _offsets(ref, y, trials, 8, block=7))
    assert np.isfinite(whole).all() and whole.shape == (10,)


def test_distance_offsets_match_a_masked_distance_matrix():
    """The compiled pass (``nearest_in_other_trials``) against the rule written out: the
    full distance matrix, a sample's own trial masked, the 3 nearest and the nearest of its
    class taken from what is left; exact and in a principal subspace."""
    from app.methods.known import KNN, ReferenceDistances, _median_offsets, _offsets

    rng = np.random.default_rng(3)
    x = rng.normal(size=(60, 6)) + np.repeat(rng.normal(size=(12, 6)) * 3, 5, axis=0)
    y, trials = np.repeat(np.arange(12), 5), rng.integers(0, 9, 60)
    trials[55:] = 4  # class 11: one trial only
    for basis in (None, ReferenceDistances.fit(x, 3).basis):
        dist = ReferenceDistances(x, basis)
        d2 = dist.to_reference(x).astype(np.float64)
        d2[trials[:, None] == trials[None, :]] = np.inf
        part = np.sort(d2, axis=1)[:, :KNN]
        own = np.where(y[:, None] == y[None, :], d2, np.inf).min(axis=1)
        expected = _median_offsets(part.mean(axis=1), part[:, 0], own, y, 12)
        assert np.isinf(own).any()  # some class has a single trial: no spacing of its own
        np.testing.assert_allclose(_offsets(dist, y, trials, 12, block=16), expected, atol=1e-4)


def test_reference_distances_exact_and_in_a_principal_subspace():
    from app.methods.known import ReferenceDistances

    rng = np.random.default_rng(0)
    # 3 strong directions plus small noise in 40 dimensions
    ref = (rng.normal(size=(60, 3)) * 10) @ rng.normal(size=(3, 40)) + 0.1 * rng.normal(
        size=(60, 40)
    )
    q = np.r_[ref[:5] + 0.05, rng.normal(size=(5, 40)) * 3]  # near references, then off-subspace
    truth = ((q[:, None, :] - ref[None, :, :]) ** 2).sum(axis=2)
    exact = ReferenceDistances.fit(ref, 0)
    assert exact.basis is None
    np.testing.assert_allclose(exact.to_reference(q), truth, rtol=1e-3, atol=1e-2)
    assert ReferenceDistances.fit(ref, 40).basis is None  # at least the rank: exact
    sub = ReferenceDistances.fit(ref, 3)
    assert sub.basis.shape == (40, 3)
    d2 = sub.to_reference(q)
    assert np.all(d2 <= truth * (1 + 1e-4) + 1e-2)  # a lower bound of the true distance
    assert np.all(np.diag(sub.to_reference(ref)) < 1e-2)  # a sample is at distance 0 from itself
    # same nearest reference, and the off-subspace queries stay far
    assert np.array_equal(d2.argmin(axis=1)[:5], truth.argmin(axis=1)[:5])
    assert d2[5:].min() > 10 * d2[:5].min(axis=1).max()
    # the fused nearest-reference pass agrees with the full distance matrix
    labels = np.arange(60) % 6
    top = np.array([0, 1, 2, 3, 4, 5, 0, 1, 2, 3])
    for dist in (exact, sub):
        full = dist.to_reference(q)
        near = dist.nearest(q, labels, top)
        expected = np.c_[
            np.sort(full, axis=1)[:, :3].mean(axis=1),
            full.min(axis=1),
            [full[i, labels == top[i]].min() for i in range(len(q))],
        ]
        np.testing.assert_allclose(near, expected, rtol=1e-4, atol=1e-3)
    with pytest.raises(ValueError, match="basis"):
        ReferenceDistances(ref, np.zeros((7, 3)))


def test_recognize_batch_is_recognize_as_arrays(enrolled, data):
    ds, *_ = data
    model, names = enrolled
    x = ds.samples
    batch = model.recognize_batch(x, top_k=6)  # more than the 4 novel classes
    answers = model.recognize(x, top_k=6)
    assert batch.answers() == answers
    assert len(batch) == len(x) and batch[2:5].answers() == answers[2:5]
    novel = batch.is_novel_class
    assert novel.any() and not novel.all()  # both classifiers answer some samples here
    assert [a.kind == "novel" for a in answers] == novel.tolist()
    # rankings from the 4 novel classes are padded with -1 and come back 4 long
    assert (batch.top_index[novel, 4:] == -1).all() and (batch.top_index[~novel] >= 0).all()
    assert {len(a.top_k) for a in answers if a.kind == "novel"} == {len(names)}


def _run_python(code: str) -> dict:
    import json
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_recognising_from_a_bundle_loads_neither_torch_nor_scikit_learn(enrolled, data, tmp_path):
    """A robot (``tactile-zsl recognize``) and every API process serving ``best`` load the
    bundle and answer without the fitting libraries, and with one BLAS thread."""
    model, _ = enrolled
    ds, _, _, _, is_test = data
    x = ds.samples[is_test][:8]
    path = tmp_path / "best.bundle"
    bundle.save(model, path)
    np.save(tmp_path / "x.npy", x)
    seen = _run_python(f"""
import json, sys
import numpy as np
from threadpoolctl import threadpool_info
from app.framework import bundle
model = bundle.load({str(path)!r})
answers = model.recognize_batch(np.load({str(tmp_path / "x.npy")!r})).records()
print(json.dumps({{"names": [a["class_name"] for a in answers],
                  "loaded": sorted(m for m in ("torch", "sklearn") if m in sys.modules),
                  "blas_threads": sorted({{p["num_threads"] for p in threadpool_info()
                                          if p["user_api"] == "blas"}})}}))
""")
    assert seen["loaded"] == [] and seen["blas_threads"] == [1], seen
    assert seen["names"] == [a["class_name"] for a in model.recognize_batch(x).records()]
