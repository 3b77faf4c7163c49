"""Attribute values beyond 0/1 in the ``best`` method: graded values as soft targets, values
not known left out, a vocabulary grown by ``with_attributes`` without refitting the forest,
(tests/methods/test_small_batch.py checks the small-batch path on such vectors)."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.linear_model import LogisticRegression

from app.data.simulator import simulate_dataset
from app.framework.errors import UnsupportedOperationError
from app.framework.registry import make_method
from app.methods.attributes import LinearAttributeModel, attribute_prior, dap_log_scores

FAST = {"n_estimators": 30, "tuning_rounds": 1, "distance_components": 8}


@pytest.fixture(scope="module")
def data():
    ds = simulate_dataset(n_objects=16, trials_per_object=4, seed=3)
    known = np.arange(12)
    return ds, ds.select_classes(known), np.arange(12, 16)


@pytest.fixture(scope="module")
def fitted(data):
    _, train, _ = data
    return make_method("best", **FAST).fit(train)


def test_a_value_not_known_drops_out_of_the_dap_product():
    rng = np.random.default_rng(0)
    p, prior = rng.uniform(0.05, 0.95, (5, 4)), rng.uniform(0.2, 0.8, 4)
    with_nan = np.array([[1.0, 0.0, np.nan, 1.0]])
    without = dap_log_scores(p[:, [0, 1, 3]], with_nan[:, [0, 1, 3]], prior[[0, 1, 3]], 0.02)
    np.testing.assert_allclose(dap_log_scores(p, with_nan, prior, 0.02), without)


def test_a_graded_value_is_a_soft_target_not_rounded():
    p, prior = np.array([[0.9], [0.2]]), np.array([0.5])
    half = dap_log_scores(p, np.array([[0.5]]), prior, 0.02)
    expected = 0.5 * np.log(p) + 0.5 * np.log1p(-p) - np.log(0.5)
    np.testing.assert_allclose(half, expected)
    assert not np.allclose(half, dap_log_scores(p, np.array([[1.0]]), prior, 0.02))


def test_0_1_targets_fit_exactly_as_plain_logistic_regression(data):
    ds, _, _ = data
    z = ds.samples.reshape(len(ds), -1)[:, :20]
    target = ds.class_attributes[ds.labels, 0]
    w, b = LinearAttributeModel.fit_one(z, target, C=0.1)
    lr = LogisticRegression(C=0.1, max_iter=1000).fit(z, target.astype(np.int64))
    np.testing.assert_array_equal(w, lr.coef_[0])
    assert b == lr.intercept_[0]


def test_an_attribute_learns_only_from_classes_whose_value_is_known(data):
    ds, _, _ = data
    z = ds.samples.reshape(len(ds), -1)[:, :20]
    target = ds.class_attributes[ds.labels, 0].astype(np.float64)
    unknown = ds.labels >= 8
    target[unknown] = np.nan
    w, b = LinearAttributeModel.fit_one(z, target, C=0.1)
    w_known, b_known = LinearAttributeModel.fit_one(z[~unknown], target[~unknown], C=0.1)
    np.testing.assert_array_equal(w, w_known)
    assert b == b_known
    # counted as 0 instead, the classifier would differ
    zeros = np.nan_to_num(target)
    assert not np.allclose(LinearAttributeModel.fit_one(z, zeros, C=0.1)[0], w)
    assert LinearAttributeModel.fit_one(z, np.full(len(z), np.nan), C=0.1) == 0.5


def test_the_prior_averages_the_known_values_only():
    a = np.array([[1.0, np.nan, 0.5], [0.0, np.nan, 1.0]], np.float32)
    np.testing.assert_allclose(attribute_prior(a), [0.5, 0.5, 0.75])


def test_with_attributes_refits_the_attributes_and_keeps_the_forest(fitted, data):
    ds, train, novel = data
    rng = np.random.default_rng(1)
    new_column = rng.integers(0, 2, train.n_classes).astype(np.float32)
    new_column[::3] = np.nan  # not known for a third of the classes
    new_column[1] = 0.5
    grown = train.with_attributes(
        (*train.attribute_names, "sticky"),
        np.column_stack([train.attribute_values, new_column]),
    )
    novel_vectors = {
        f"new-{i}": np.r_[ds.class_attributes[c], np.nan if i % 2 else 1.0]
        for i, c in enumerate(novel)
    }
    model = fitted.with_attributes(grown, novel_vectors)
    assert model.registry.attribute_names[-1] == "sticky"
    assert model.registry.novel_names == list(novel_vectors)
    x = ds.samples[np.isin(ds.labels, novel)]
    np.testing.assert_array_equal(model.known_proba(x), fitted.known_proba(x))
    np.testing.assert_array_equal(model.novelty_score(x), fitted.novelty_score(x))
    proba = model.attribute_proba(x)
    assert proba.shape == (len(x), train.n_attributes + 1)
    np.testing.assert_array_equal(proba[:, :-1], fitted.attribute_proba(x))
    # the new attribute's classifier: trained on the classes whose value is known only
    target = new_column[train.labels].astype(np.float64)
    expected = LinearAttributeModel.fit_one(
        fitted.known_.cues_model.scaled(train.samples.reshape(len(train), -1)), target, C=0.1
    )
    np.testing.assert_allclose(model.attributes_.weights[-1], expected[0])
    assert proba[:, -1].std() > 0
    assert fitted.registry.attribute_names == train.attribute_names  # the base is untouched


def test_with_attributes_refuses_other_classes(fitted, data):
    ds, train, _ = data
    other = ds.select_classes(np.arange(1, 13))
    with pytest.raises(Exception, match="known classes the model was fitted on"):
        fitted.with_attributes(other)


def test_the_paper_pipeline_is_fitted_again_instead(data):
    _, train, _ = data
    paper = make_method("paper")
    paper.input_shape = train.input_shape  # fitted enough for the refusal to be reached
    with pytest.raises(UnsupportedOperationError, match="fit it again"):
        paper.with_attributes(train)


def test_best_fits_on_a_dataset_of_graded_and_unknown_values(data):
    ds, train, novel = data
    values = train.attribute_values.copy()
    values[0, :4] = np.nan
    values[1, 0] = 0.5
    values[:, 2] = np.where(np.arange(len(values)) % 2, np.nan, 0.25)
    graded = train.with_attributes(train.attribute_names, values)
    assert not graded.binary_attributes
    model = make_method("best", **FAST).fit(graded)
    np.testing.assert_array_equal(model.registry.known_attributes, values)
    assert model.attributes_.constant[2] == 0.25  # every known value of it is 0.25
    grown = model.add_novel_classes(["n"], [np.r_[ds.class_attributes[novel[0]]]])
    p = grown.novel_proba(ds.samples[ds.labels == novel[0]])
    assert np.isfinite(p).all() and np.allclose(p.sum(axis=1), 1)
    with pytest.raises(Exception, match="graded or not-known"):
        make_method("dap").fit(graded)
