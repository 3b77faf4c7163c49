"""``auto`` (``MethodChoice``): a probe of the training data chooses the method, which is then
fitted on all of it; the probe's verdict follows the data (the simulator's many objects
against PHAC-2's real ones), never the catalogue's size alone."""

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.framework.bundle import from_bytes, to_bytes
from app.framework.errors import FrameworkError
from app.framework.registry import make_method, method_class
from app.methods.best import BestRecognizer
from app.methods.choice import CANDIDATES, MethodChoice
from app.methods.prototypes import PrototypeRecognizer


def test_it_shares_its_candidates_class_traits_so_a_service_can_ask_before_a_model():
    traits = (
        "novel_part_separable",
        "learns_classes_from_samples",
        "graded_attributes",
        "attributes_separable",
        "learns_known_incrementally",
    )
    for name in CANDIDATES:
        for trait in traits:
            assert getattr(method_class(name), trait) == getattr(MethodChoice, trait), (name, trait)


@pytest.mark.parametrize(
    ("params", "named"),
    [
        ({"candidates": ("best", "nosuch")}, "nosuch"),
        ({"candidates": ("auto",)}, "auto"),
        ({"candidates": ()}, "at least one"),
        ({"params": {"paper": {}}}, "paper"),
        ({"probe_novel": 1.5}, "probe_novel"),
        ({"probe_classes": 2}, "probe_classes"),
        ({"probe_folds": 0}, "probe_folds"),
    ],
)
def test_bad_settings_are_refused_before_any_work_naming_the_problem(params, named):
    with pytest.raises(FrameworkError, match=named):
        MethodChoice(**params).fit(simulate_dataset(4, 3, seed=0))


def test_fit_refuses_what_is_not_a_dataset():
    with pytest.raises(FrameworkError, match="got ndarray"):
        MethodChoice().fit(np.zeros((3, 4)))


@pytest.fixture(scope="module")
def simulated_many():
    """40 simulated objects, 6 trials each: near-Gaussian classes, where a forest's accuracy
    already falls behind a discriminant space (docs/BENCHMARKS.md)."""
    ds = simulate_dataset(40, 6, seed=3)
    return make_method("auto", seed=0, probe_folds=2).fit(ds), ds


def test_on_many_simulated_objects_the_probe_measures_prototypes_ahead(simulated_many):
    model, ds = simulated_many
    chosen = model.metrics["chosen_by"]
    probe = chosen["probe"]
    assert set(probe) == set(CANDIDATES)
    for figures in probe.values():
        assert 0.0 <= figures["known_acc"] <= 1.0 and 0.0 <= figures["nd_auroc"] <= 1.0
        assert figures["score"] == pytest.approx(figures["known_acc"] + figures["nd_auroc"])
    assert probe["prototypes"]["score"] > probe["best"]["score"] + 0.05
    assert chosen["method"] == "prototypes"
    assert isinstance(model, PrototypeRecognizer)
    assert model.registry.known_names == list(ds.class_names)  # fitted on every class


def test_the_chosen_model_and_its_choice_survive_a_bundle(simulated_many):
    model, ds = simulated_many
    again = from_bytes(to_bytes(model))
    assert type(again) is PrototypeRecognizer
    assert again.metrics["chosen_by"] == model.metrics["chosen_by"]
    x = ds.samples[:20]
    np.testing.assert_allclose(again.known_proba(x), model.known_proba(x), atol=1e-6)


def test_a_single_candidate_needs_no_probe():
    ds = simulate_dataset(6, 4, seed=0)
    model = MethodChoice(candidates=("prototypes",)).fit(ds)
    assert isinstance(model, PrototypeRecognizer)
    assert model.metrics["chosen_by"]["probe"] == {}


def test_too_few_classes_for_a_probe_fall_back_to_the_rule():
    ds = simulate_dataset(2, 4, seed=0)
    model = MethodChoice(candidates=("prototypes", "best")).fit(ds)
    assert isinstance(model, BestRecognizer)
    chosen = model.metrics["chosen_by"]
    assert (chosen["method"], chosen["reason"], chosen["probe"]) == ("best", "rule", {})
    alone = MethodChoice(candidates=("prototypes",)).fit(ds).metrics["chosen_by"]
    assert (alone["method"], alone["reason"]) == ("prototypes", "only candidate")


def test_unprobed_must_be_a_candidate():
    with pytest.raises(FrameworkError, match="unprobed"):
        MethodChoice(candidates=("prototypes",), unprobed="best").fit(simulate_dataset(2, 2))


def test_where_the_catalogue_outgrows_the_probe_its_figures_say_so(simulated_many):
    """40 classes, a probe of at most 10: the record names both sizes and gives the fitted
    model's own held-out accuracy at full size."""
    ds = simulated_many[1]
    model = MethodChoice(seed=0, probe_folds=1, probe_classes=10).fit(ds)
    chosen = model.metrics["chosen_by"]
    assert (chosen["n_classes"], chosen["probe_classes"]) == (40, 10)
    assert "probe of 10 of 40 classes" in chosen["probe_note"]
    if chosen["method"] == "prototypes":
        assert chosen["full_size_known_acc"] == model.metrics["probe_known_acc"]
    else:
        assert chosen["full_size_known_acc"] is None and chosen["full_size_note"]


@pytest.mark.phac2
def test_on_phac2_the_probe_measures_the_forest_ahead(phac2_path):
    """PHAC-2's real objects: ``best`` detects novel objects better (docs/RESULTS.md), and
    the probe, which sees only training data, finds it too."""
    from app.data.phac2 import load_phac2

    dataset = load_phac2(phac2_path)
    probe = MethodChoice(seed=0, probe_folds=2).probe(dataset)
    assert probe["best"]["score"] > probe["prototypes"]["score"], probe
    assert MethodChoice(seed=0, probe_folds=2).probe(dataset) == probe  # by its seed


def test_a_candidate_without_threads_gets_only_the_settings_it_takes():
    """``paper`` takes a seed but no ``n_jobs``: the choice passes it what it has."""
    model = MethodChoice(candidates=("paper",), params={"paper": {"encoder_epochs": 1}})._make(
        "paper"
    )
    assert model.get_params()["seed"] == 0 and model.get_params()["encoder_epochs"] == 1
