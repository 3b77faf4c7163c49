"""The parts of ``best`` whose cost grows with the samples, not samples x objects: the forest
grown on class codes, its sparse leaves, the approximate neighbour index against exact
search, and the one-pass statistics that replaced a pass per class."""

from __future__ import annotations

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.framework import bundle
from app.framework.novelty import novelty_validation_split
from app.framework.registry import make_method
from app.framework.scaling import RobustInputScaler, flatten
from app.methods.forest import FlatForest, _leaf_distributions
from app.methods.known import ReferenceDistances, _offsets, class_means, fisher_weights


@pytest.fixture(scope="module")
def sim():
    """40 simulated objects, 8 trials each: 6 trials of each train, 2 test."""
    ds = simulate_dataset(40, 8, seed=3)
    test = (ds.trials % 8) >= 6
    scaler = RobustInputScaler().fit(flatten(ds.samples[~test]))
    z = scaler.transform(flatten(ds.samples))
    return ds, z, test


def test_leaf_distributions_are_each_leafs_class_shares():
    rng = np.random.default_rng(0)
    leaf, y = rng.integers(0, 9, 300), rng.integers(0, 5, 300)
    rows, cols, values = _leaf_distributions(leaf, y, 5)
    dense = np.zeros((9, 5))
    np.add.at(dense, (leaf, y), 1.0)
    dense /= dense.sum(axis=1, keepdims=True)
    rebuilt = np.zeros((9, 5))
    rebuilt[rows, cols] = values
    np.testing.assert_allclose(rebuilt, dense, atol=1e-15)
    # ordered by leaf then class, as FlatForest's compressed rows need
    assert np.all(np.diff(rows * 5 + cols) > 0)


def test_code_forest_leaves_are_pure_and_it_classifies_like_the_classifier(sim):
    ds, z, test = sim
    y = ds.labels
    grown = FlatForest.grow(
        z[~test], y[~test], 40, 60, "sqrt", 0, 1, "sklearn", codes=32, trees_at_once=7
    )
    assert grown.n_trees == 60  # grown 7 at a time, the last chunk smaller
    # distinct samples end in leaves of one class: the training samples are recognised
    assert (grown.predict_proba(z[~test]).argmax(axis=1) == y[~test]).all()
    leaves = grown.nodes[:, 0] < 0
    assert (grown.nodes[leaves, 3] >= 0).all() and len(grown.mixed_class) == 0
    classifier = FlatForest.grow(z[~test], y[~test], 40, 60, "sqrt", 0, 1, "sklearn", codes=0)
    acc = {
        name: (f.predict_proba(z[test]).argmax(axis=1) == y[test]).mean()
        for name, f in (("codes", grown), ("classifier", classifier))
    }
    assert acc["codes"] > 0.5 and abs(acc["codes"] - acc["classifier"]) < 0.15, acc
    rows = grown.predict_proba(z[test])
    np.testing.assert_allclose(rows.sum(axis=1), 1.0, atol=1e-12)
    again = FlatForest.from_state(grown.get_state(), 40, z.shape[1])
    assert again.predict_proba(z[test]).tobytes() == rows.tobytes()


def test_code_forest_is_reproducible_from_its_seed(sim):
    ds, z, test = sim
    args = (z[~test], ds.labels[~test], 40, 12, "sqrt")
    a = FlatForest.grow(*args, 5, 1, "sklearn", codes=16)
    b = FlatForest.grow(*args, 5, 1, "sklearn", codes=16)
    c = FlatForest.grow(*args, 6, 1, "sklearn", codes=16)
    assert a.predict_proba(z[test]).tobytes() == b.predict_proba(z[test]).tobytes()
    assert a.predict_proba(z[test]).tobytes() != c.predict_proba(z[test]).tobytes()


def test_class_means_and_weights_match_a_mask_per_class(sim):
    ds, z, _ = sim
    y = ds.labels
    expected = np.stack([z[y == c].mean(axis=0, dtype=np.float64) for c in range(40)])
    np.testing.assert_allclose(class_means(z, y, 40), expected, rtol=1e-10, atol=1e-10)
    w = fisher_weights(z, y, 40)
    assert w.dtype == np.float32 and w.shape == (z.shape[1],) and (w > 0).all()


@pytest.mark.parametrize("components", [0, 16])
def test_index_finds_the_exact_neighbours_on_small_data(sim, components):
    """Through the HNSW graph, the nearest reference is the exact one for nearly every
    query; a distance it returns is never below the exact one (it is the distance to a
    real reference sample), and the nearest sample of a class is exact."""
    ds, z, test = sim
    ref, q = z[~test], z[test]
    labels = ds.labels[~test]
    exact = ReferenceDistances.fit(ref, components)
    approx = ReferenceDistances.fit(ref, components, approximate_above=10)
    assert exact.index is None and approx.index is not None
    top = np.random.default_rng(0).integers(0, 40, len(q))
    e, a = exact.nearest(q, labels, top), approx.nearest(q, labels, top)
    scale = np.maximum(e, 1e-3)
    assert np.mean(np.isclose(a[:, 1], e[:, 1], rtol=1e-3)) >= 0.97
    assert (a[:, :2] >= e[:, :2] - 1e-3 * scale[:, :2]).all()
    np.testing.assert_allclose(a[:, 2], e[:, 2], rtol=1e-3, atol=1e-3)
    # the per-class trial spacings and global offsets, through the graph and exactly
    y, trials = labels, ds.trials[~test]
    np.testing.assert_allclose(
        _offsets(approx, y, trials, 40), _offsets(exact, y, trials, 40), atol=0.05
    )


def test_points_learnt_after_the_graph_are_searched_exactly_beside_it(sim, monkeypatch):
    """A promotion's points join the index's tail, not its graph (whose stored bytes then
    stay the same part): searched exactly and merged, they are found as exact search finds
    them, and the answers survive a bundle round trip; past its bound the tail goes into a
    copy of the graph."""
    from app.methods import neighbours

    ds, z, test = sim
    ref, q = z[~test], z[test]
    base = ReferenceDistances.fit(ref[:-40], 16, approximate_above=10)
    grown = base.with_points(ref[-40:])
    assert grown.index.index is base.index.index and len(grown.index.tail) == 40
    assert grown.index.to_bytes() is base.index.to_bytes()
    d2, ids = grown.index.search(grown.coordinates(ref[-40:]), 3)
    np.testing.assert_array_equal(ids[:, 0], len(ref) - 40 + np.arange(40))  # each itself
    np.testing.assert_allclose(d2[:, 0], 0.0, atol=1e-3)
    assert (np.diff(d2, axis=1) >= 0).all()
    labels = ds.labels[~test]
    top = np.random.default_rng(1).integers(0, 40, len(q))
    exact = ReferenceDistances(ref, base.basis, center=base.center).nearest(q, labels, top)
    near = grown.nearest(q, labels, top)
    assert np.mean(np.isclose(near[:, 1], exact[:, 1], rtol=1e-3)) >= 0.97
    stored = ReferenceDistances(grown.reference, grown.basis, grown.index.to_bytes(), grown.center)
    np.testing.assert_array_equal(stored.nearest(q, labels, top), near)
    monkeypatch.setattr(neighbours, "TAIL_POINTS", 10)
    monkeypatch.setattr(neighbours, "TAIL_SHARE", 0.0)
    taken = base.with_points(ref[-40:])
    assert taken.index.index is not base.index.index and len(taken.index.tail) == 0
    assert taken.index.index.ntotal == len(ref) and base.index.index.ntotal == len(ref) - 40


@pytest.mark.parametrize("components", [0, 16])
def test_a_reference_grows_in_place_to_the_bits_a_load_computes(sim, monkeypatch, components):
    """Samples a promotion adds are appended behind the reference and its projections (the
    earlier ones are not copied, nor projected again), and the result is bit for bit what
    a load of the same reference computes, across projection blocks."""
    from app.methods import known

    monkeypatch.setattr(known, "_PROJECTED_ROWS", 50)
    ds, z, test = sim
    ref, q, labels = z[~test], z[test], ds.labels[~test]
    top = np.random.default_rng(2).integers(0, 40, len(q))
    base = ReferenceDistances.fit(ref[:-30], components, approximate_above=10)
    top_before = top % (labels[:-30].max() + 1)  # classes the base's reference holds
    before = base.nearest(q, labels[:-30], top_before)
    once = base.with_points(ref[-30:-10])
    twice = once.with_points(ref[-10:])
    for key in ("reference", "_ref", "_ref_sq", "_points"):
        assert np.shares_memory(getattr(twice, key), getattr(base, key)), key
    stored = ReferenceDistances(twice.reference, twice.basis, twice.index.to_bytes(), twice.center)
    for key in ("reference", "_ref", "_ref_res", "_ref_sq", "_points"):
        np.testing.assert_array_equal(getattr(twice, key), getattr(stored, key), err_msg=key)
    np.testing.assert_array_equal(twice.nearest(q, labels, top), stored.nearest(q, labels, top))
    np.testing.assert_array_equal(base.nearest(q, labels[:-30], top_before), before)
    assert len(once.reference) == len(ref) - 10


def test_novelty_split_holds_out_whole_trials_per_class():
    ds = simulate_dataset(30, 5, seed=1)
    fit, known, val = novelty_validation_split(ds, 0.1, 1, seed=4)
    assert len(np.intersect1d(fit, known)) == 0 and len(np.intersect1d(fit, val)) == 0
    val_classes = np.unique(ds.labels[val])
    assert len(val_classes) == 3 and not np.isin(ds.labels[fit], val_classes).any()
    # one whole trial of every other class is held out, and only that one
    for c in np.setdiff1d(np.arange(30), val_classes):
        assert len(np.unique(ds.trials[known][ds.labels[known] == c])) == 1
    assert len(fit) + len(known) + len(val) == len(ds)
    again = novelty_validation_split(ds, 0.1, 1, seed=4)
    assert all(np.array_equal(a, b) for a, b in zip((fit, known, val), again, strict=True))


@pytest.fixture(scope="module")
def indexed_model(sim):
    ds, _, test = sim
    train = ds.subset(np.flatnonzero(~test))
    return make_method("best", n_estimators=20, tuning_rounds=1, approximate_above=50, seed=2).fit(
        train
    ), ds.samples[test]


def test_a_model_with_an_index_answers_the_same_after_a_bundle_round_trip(indexed_model):
    model, x = indexed_model
    assert model.known_.cues_model.distances.index is not None
    loaded = bundle.from_bytes(bundle.to_bytes(model))
    assert loaded.known_.cues_model.distances.index is not None
    for n in (1, len(x)):  # one sample takes the small-batch scorer, through the index too
        a, b = model.recognize_batch(x[:n]), loaded.recognize_batch(x[:n])
        assert a.top_index.tobytes() == b.top_index.tobytes()
        assert a.novelty_score.tobytes() == b.novelty_score.tobytes()
    assert model._small_batch.constants.indexed is model.known_.cues_model.distances


def test_a_damaged_index_is_refused(indexed_model):
    model, _ = indexed_model
    meta, arrays = model.get_state()
    arrays["known/index"] = arrays["known/index"][:100]
    fresh = make_method("best")
    fresh.registry, fresh.input_shape = model.registry, model.input_shape
    fresh.featurizer_, fresh.novelty_threshold = None, model.novelty_threshold
    with pytest.raises(ValueError, match="neighbour index"):
        fresh.set_state(meta, arrays)


def test_a_bundle_without_the_new_parameters_loads_as_what_it_was_made_with(indexed_model):
    model, _ = indexed_model
    meta, arrays = model.get_state()
    names = ("forest_codes", "approximate_above", "tuning_objects", "attribute_samples")
    for name in (*names, "forest_grower"):
        meta["params"].pop(name)
    fresh = make_method("best")
    fresh.registry, fresh.input_shape = model.registry, model.input_shape
    fresh.set_state(meta, arrays)
    assert [fresh.get_params()[name] for name in names] == [0, 0, 0, 0]
    # grown by scikit-learn, as every bundle before the compiled grower: a refit grows so
    assert fresh.get_params()["forest_grower"] == "sklearn"


def test_enrolment_shares_the_fitted_parts_instead_of_copying_them(indexed_model):
    """Enrolment derives a new model by deep copy; the known part (reference samples, index,
    forest) and the attribute model are never changed after a fit, so both models hold the
    same objects, and the base still answers as before."""
    model, x = indexed_model
    before = model.recognize_batch(x)
    vector = np.zeros((1, len(model.registry.attribute_names)), np.float32)
    vector[0, :3] = 1
    enrolled = model.add_novel_classes(["new"], vector).add_one_shot("new", x[:1])
    assert enrolled.known_ is model.known_ and enrolled.attributes_ is model.attributes_
    assert enrolled.registry is not model.registry and model.registry.novel_names == []
    after = model.recognize_batch(x)
    assert after.top_index.tobytes() == before.top_index.tobytes()


def test_versions_loaded_from_the_same_parts_share_their_known_part(sim):
    """An API process loads each new version from the store's read-only parts: the cues of
    parts it already holds (reference projection, neighbour index, forest walk) are not
    built again; loaded from other arrays, they are."""
    ds = sim[0]
    model = make_method("best", n_estimators=10, approximate_above=100, by_procedure=False)
    model = model.fit(ds)
    head, parts = bundle.split(model)
    decoded = {sha: bundle.decode_part(blob) for sha, blob in parts.items()}
    for array in decoded.values():
        bundle.freeze(array)  # as bundles.PartCache holds them
    first = bundle.from_bytes(head, part=decoded.__getitem__)
    again = bundle.from_bytes(head, part=decoded.__getitem__)
    assert first.known_.cues_model.distances.index is not None
    assert again.known_.cues_model is first.known_.cues_model
    fresh = bundle.from_bytes(head, part=lambda sha: bundle.decode_part(parts[sha]))
    assert fresh.known_.cues_model is not first.known_.cues_model
    x = ds.samples[:5]
    np.testing.assert_array_equal(fresh.known_proba(x), again.known_proba(x))
    np.testing.assert_array_equal(fresh.novelty_score(x), again.novelty_score(x))
