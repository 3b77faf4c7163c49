"""Classes without attributes (M = 0): known-object recognition with best, the paper's
pipeline and the extra-trees baseline; zero-shot refused; novel classes from samples."""

from __future__ import annotations

import numpy as np
import pytest

from app.data.dataset import TactileDataset
from app.data.simulator import simulate_dataset
from app.framework import bundle
from app.framework.errors import (
    DuplicateClassError,
    UnsupportedOperationError,
    ZeroShotUnavailableError,
)
from app.framework.registry import make_method

from .conftest import QUICK

FAST = {
    "best": dict(n_estimators=40, tuning_rounds=1),
    "paper": dict(QUICK, encoder_epochs=15),
    "extratrees": dict(n_estimators=60, n_jobs=1),
}


def without_attributes(ds: TactileDataset) -> TactileDataset:
    return TactileDataset(
        samples=ds.samples,
        labels=ds.labels,
        trials=ds.trials,
        class_attributes=np.zeros((ds.n_classes, 0), np.float32),
        attribute_names=(),
        class_names=ds.class_names,
        name="no-attributes",
    )


@pytest.fixture(scope="module")
def data():
    ds = simulate_dataset(n_objects=8, trials_per_object=6, seed=4)
    trial_no = np.arange(len(ds)) % 6  # samples come by object, then trial
    return {
        "train": without_attributes(ds.select_classes(np.arange(6)).subset(trial_no[: 6 * 6] < 5)),
        "test": ds.select_classes(np.arange(6)).subset(trial_no[: 6 * 6] == 5),
        "novel": ds.select_classes([6, 7]),
    }


@pytest.fixture(scope="module", params=["best", "paper", "extratrees"])
def fitted(request, data):
    return make_method(request.param, **FAST[request.param]).fit(data["train"])


def test_a_dataset_without_attributes_fits_for_known_objects(fitted, data):
    assert fitted.registry.attribute_names == ()
    assert fitted.registry.known_attributes.shape == (6, 0)
    assert not fitted.has_attributes
    test = data["test"]
    accuracy = np.mean(fitted.known_proba(test.samples).argmax(axis=1) == test.labels)
    assert accuracy >= 0.8, accuracy
    answers = fitted.recognize_batch(test.samples)
    assert len(answers) == len(test) and (answers.top_index[:, 0] < 6).all()
    assert np.isfinite(fitted.novelty_threshold)


def test_zero_shot_enrolment_is_refused_with_the_reason(fitted):
    with pytest.raises(ZeroShotUnavailableError) as info:
        fitted.add_novel_classes(["sponge"], np.zeros((1, 0), np.float32))
    message = str(info.value)
    assert "a class without attributes cannot be recognised zero-shot; add samples" in message
    assert isinstance(info.value, UnsupportedOperationError)  # the service's 409


def test_the_paper_pipeline_without_attributes_has_no_generator(data):
    model = make_method("paper", **FAST["paper"]).fit(data["train"])
    assert model.generator_ is None and model.discriminator_ is None
    assert model.metrics["alg1_final_loss"] is None
    loaded = bundle.from_bytes(bundle.to_bytes(model))
    x = data["test"].samples
    np.testing.assert_allclose(loaded.known_proba(x), model.known_proba(x), atol=1e-6)
    assert loaded.generator_ is None


def test_best_without_attributes_round_trips_and_describes_nothing(data):
    model = make_method("best", **FAST["best"]).fit(data["train"])
    x = data["test"].samples
    assert model.attribute_proba(x).shape == (len(x), 0)
    loaded = bundle.from_bytes(bundle.to_bytes(model))
    np.testing.assert_array_equal(loaded.known_proba(x), model.known_proba(x))
    np.testing.assert_array_equal(loaded.novelty_score(x), model.novelty_score(x))


def test_best_learns_novel_classes_from_samples_alone(data):
    model = make_method("best", **FAST["best"]).fit(data["train"])
    novel = data["novel"]
    trial_no = np.arange(len(novel)) % 6
    shots = {
        name: novel.samples[(novel.labels == k) & (trial_no == 0)]
        for k, name in enumerate(novel.class_names)
    }
    grown = model.add_novel_classes_from_samples(shots)
    assert grown.registry.novel_names == list(novel.class_names)
    assert grown.registry.novel_attributes.shape == (2, 0)
    test = novel.subset(trial_no != 0)
    p = grown.novel_proba(test.samples)
    assert p.shape == (len(test), 2)
    np.testing.assert_allclose(p.sum(axis=1), 1.0)
    assert np.mean(p.argmax(axis=1) == test.labels) >= 0.8
    # every answer routed to the novel part names one of them
    routed = grown.recognize_batch(test.samples)
    novel_rows = routed.is_novel
    assert set(routed.top_index[novel_rows, 0].tolist()) <= {6, 7}
    # more samples come as one-shot samples; the model keeps going after a round trip
    more = grown.add_one_shot(novel.class_names[0], test.samples[:1])
    loaded = bundle.from_bytes(bundle.to_bytes(more))
    np.testing.assert_array_equal(loaded.novel_proba(test.samples), more.novel_proba(test.samples))
    assert len(loaded.without_novel_classes().registry.novel_names) == 0
    with pytest.raises(DuplicateClassError, match="already exists"):
        grown.add_novel_classes_from_samples({novel.class_names[0]: test.samples[:1]})


def test_classes_from_samples_alone_are_refused_where_they_cannot_be_recognised(data):
    paper = make_method("paper", **FAST["paper"]).fit(data["train"])
    x = data["novel"].samples[:2]
    with pytest.raises(UnsupportedOperationError, match="method 'paper' cannot recognise"):
        paper.add_novel_classes_from_samples({"new": x})
    described = simulate_dataset(n_objects=6, trials_per_object=4, seed=2)
    best = make_method("best", **FAST["best"]).fit(described)
    # best takes such a class on a model with attributes too: not known for any of them
    grown = best.add_novel_classes_from_samples({"new": described.samples[:1]})
    assert np.isnan(grown.registry.novel_attributes[0]).all()
    assert grown.recognize_batch(described.samples[:1]).class_names[-1] == "new"
    dap = make_method("dap").fit(described)
    with pytest.raises(UnsupportedOperationError, match="describes classes by attributes"):
        dap.add_novel_classes_from_samples({"new": described.samples[:1]})
