"""Hyper-parameters in scikit-learn's manner, for every registered method: names from the
constructor's signature, constructors that only store, constraints checked by fit,
every parameter documented, and the parameter names model bundles carry unchanged."""

from __future__ import annotations

import inspect
import re

import pytest

from app.baselines.common import ForestBaseline
from app.baselines.dap import DAPRecognizer
from app.framework.errors import FrameworkError
from app.framework.paper import PaperFeatureGMMRecognizer, PaperRecognizer
from app.framework.params import Constraint, at_least, between, either, integer, number, one_of
from app.framework.recognizer import TactileRecognizer
from app.framework.registry import METHODS, method_class

CLASSES = [method_class(name) for name in METHODS]


def _signature(cls: type) -> dict[str, object]:
    params = inspect.signature(cls.__init__).parameters.values()
    return {p.name: p.default for p in params if p.name != "self"}


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.method)
def test_get_params_follow_the_signature_and_rebuild_the_method(cls):
    model = cls()
    params = model.get_params()
    assert list(params) == list(_signature(cls))
    assert params == _signature(cls)  # the constructor stores each argument as it is
    again = cls(**params)
    assert again.get_params() == params


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.method)
def test_set_params_sets_known_names_and_refuses_others(cls):
    model = cls()
    name = next(iter(model.get_params()))
    value = model.get_params()[name]
    assert model.set_params(**{name: value}) is model
    with pytest.raises(FrameworkError, match="invalid parameter 'no_such_parameter'"):
        model.set_params(no_such_parameter=1)


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.method)
def test_constructors_only_store_and_constraints_name_real_attributes(cls):
    junk = {name: object() for name in cls._parameter_constraints if name in _signature(cls)}
    model = cls(**junk)  # no check in the constructor
    assert all(getattr(model, name) is value for name, value in junk.items())
    default = cls()
    for name in cls._parameter_constraints:
        assert hasattr(default, name), name
    default._validate_params()  # the defaults pass


def _documented(cls: type) -> set[str]:
    """The names in the numpydoc "Parameters" section of ``cls``'s own docstring."""
    doc = inspect.cleandoc(cls.__doc__ or "")
    match = re.search(r"^Parameters\n-+\n(.*?)(?:\n\n[A-Z][a-z]+\n-+\n|\Z)", doc, re.M | re.S)
    if not match:
        return set()
    names = set()
    for line in match.group(1).splitlines():
        if line and not line[0].isspace():
            names |= {n.strip() for n in line.split(" : ")[0].split(",")}
    return names


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.method)
def test_every_hyper_parameter_is_documented(cls):
    documented = _documented(cls)
    # a subclass may document only what differs and refer to its parent for the rest
    for base in cls.__mro__[1:]:
        if issubclass(base, TactileRecognizer) and cls.__doc__ and base.__name__ in cls.__doc__:
            documented |= _documented(base)
    assert set(_signature(cls)) <= documented, set(_signature(cls)) - documented


def test_paper_parameters_are_explained_in_the_papers_terms():
    doc = PaperRecognizer.__doc__
    for term in ("Algorithm 1", "Algorithm 2", "σ_D", "σ_G", "Sect. VI-B", "NEIGHB-F", "GEN-F"):
        assert term in doc, term


@pytest.mark.parametrize(
    "child, parent, differ",
    [
        (PaperFeatureGMMRecognizer, PaperRecognizer, {"novelty_space"}),
        (DAPRecognizer, ForestBaseline, set()),
        (method_class("eszsl"), ForestBaseline, set()),
        (method_class("extratrees"), ForestBaseline, set()),
        (method_class("extratrees"), DAPRecognizer, set()),
    ],
)
def test_subclasses_keep_their_parents_defaults(child, parent, differ):
    mine, theirs = _signature(child), _signature(parent)
    shared = set(mine) & set(theirs)
    assert {n for n in shared if mine[n] != theirs[n]} == differ
    if parent is not DAPRecognizer:
        assert set(theirs) <= set(mine)  # every parameter of the parent is the child's too


def test_bundles_carry_the_parameter_names_they_always_had():
    # what bundles saved before get_params came from the signature list (and must load);
    # featurizer_params came with raw-trial models, last, and bundles without it load with
    # its default (tests/framework/test_raw_trials.py)
    assert PaperRecognizer().get_params().keys() - {"featurizer_params"} == {
        "seed", "encoder_epochs", "lr", "weight_decay", "batch_size", "mlp_hidden",
        "mlp_features", "mlp_dropout", "input_clip", "alg1_epochs", "alg2_epochs", "sigma_d",
        "sigma_g", "max_phase_steps", "noise_std", "samples_per_class", "fc_z_epochs",
        "synthesis", "one_shot_k", "finetune_steps", "gmm_components", "gmm_covariance",
        "novelty_pca_dims", "novelty_space", "novelty_val_fraction",
    }  # fmt: skip
    assert list(method_class("best")().get_params()) == [
        "seed", "n_estimators", "max_features", "attribute_C", "attribute_samples", "dap_clip",
        "shot_temperature", "knn_weight", "top_weight", "novelty_val_fraction",
        "novelty_holdout_trials",
        "tuning_rounds", "tuning_objects", "distance_components", "forest_grower", "forest_codes",
        "approximate_above", "sae_lambda", "sae_temperature", "n_jobs", "featurizer_params",
        "by_procedure", "procedure_estimators", "shot_margin",
    ]  # fmt: skip
    # tuning_objects, forest_codes, approximate_above and attribute_samples came with the
    # forest grown on class codes; a bundle without them loads as what it was made with (0:
    # every tuning round, a classifier's forest, exact distances, every sample;
    # tests/methods/test_scale_parts.py); by_procedure came with answers from some
    # procedures, and a bundle without it loads as one whole model (False);
    # procedure_estimators came later, and a bundle without it refits its per-procedure
    # models with n_estimators trees, as it was made (None); forest_grower came with the
    # compiled Gini grower, and a bundle without it grows scikit-learn's trees ("sklearn");
    # shot_margin came with the one-shot bound (2026-11-28), and a bundle without it loads
    # with today's default


def test_a_constructor_with_kwargs_is_refused():
    class Loose(TactileRecognizer):
        def __init__(self, **params):
            super().__init__()

    with pytest.raises(TypeError, match="must name every hyper-parameter"):
        Loose._get_param_names()


@pytest.mark.parametrize(
    "constraint, good, bad, message",
    [
        (one_of(("a", "b")), "a", "c", "x must be one of ('a', 'b'), got 'c'"),
        (at_least(1), 2.0, 0, "x must be at least 1, got 0"),
        (at_least(1), 1, None, "x must be at least 1, got None"),
        (between(0, 1), 0.5, 1, "x must lie in (0, 1), got 1"),
        (between(0, 1), 0.5, "a", "x must lie in (0, 1), got 'a'"),
        (integer(1), True, 1.0, "x must be a positive integer, got 1.0"),
        (integer(0, allow_bool=False), 0, False, "x must be an integer of at least 0, got False"),
        (number(0), 1e-9, 0, "x must be positive, got 0"),
        (number(0, include_low=True, finite=True), 0, float("inf"),
         "x must be a non-negative number, got inf"),
        (number(0, 0.5), 0.25, 0.5, "x must lie in (0, 0.5), got 0.5"),
        (either(one_of((None,)), number(0), must="be positive or None"), None, -1,
         "x must be positive or None, got -1"),
        (Constraint(lambda v: len(v) > 1, "have 2 items"), (1, 2), 3, "x must have 2 items, got 3"),
    ],
)  # fmt: skip
def test_constraints_say_what_the_value_must_be(constraint, good, bad, message):
    constraint.check("x", good)
    with pytest.raises(FrameworkError) as raised:
        constraint.check("x", bad)
    assert str(raised.value) == message


def test_train_refuses_a_bad_parameter_before_training(tmp_path, capsys):
    from app.cli import main

    out = tmp_path / "model.bundle"
    code = main(["train", "--dataset", "simulated:6", "--method", "best", "--quiet",
                 "--param", "n_estimators=0", "--out", str(out)])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and "n_estimators must be a positive integer, got 0" in err
    assert "training" not in err and not out.exists()
