"""Every registered method fits every dataset shape that enrolment and ``serve --dataset``
accept, and answers: a service learning from a robot starts at 2 classes of 2 enrolled
samples (each sample its own trial), grows classes of 1 or 2 trials beside larger ones,
and may hold raw trials, no procedure layout or no attributes. ``auto`` must fit wherever
one of its candidates does, and says how it chose."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.framework.registry import METHODS, make_method
from app.testing.service import QUICK_PARAMS
from tests.framework.raw_data import synthetic_biotac

FAST_BEST = {"n_estimators": 30, "tuning_rounds": 1}
FAST = {
    "paper": QUICK_PARAMS,
    "paper-fgmm": QUICK_PARAMS,
    "best": FAST_BEST,
    "extratrees": {"n_estimators": 30},
    # one fold keeps the probe to seconds; its rule and its probe are what is walked here
    "auto": {"probe_folds": 1, "params": {"best": FAST_BEST}},
}


def _uneven():
    """4 classes of 5 trials beside one of 1 trial and one of 2."""
    ds = simulate_dataset(6, 5, seed=4)
    t = ds.trials % 5
    keep = (ds.labels < 4) | ((ds.labels == 4) & (t == 0)) | ((ds.labels == 5) & (t < 2))
    return ds.subset(np.flatnonzero(keep))


def _without_attributes():
    ds = simulate_dataset(3, 3, seed=5)
    return dataclasses.replace(
        ds, class_attributes=np.zeros((ds.n_classes, 0), np.float32), attribute_names=()
    )


def _without_procedures():
    return dataclasses.replace(simulate_dataset(3, 3, seed=5), procedures=())


SHAPES = {
    "2 classes x 2 samples": lambda: simulate_dataset(2, 2, seed=3),
    "4 classes x 2 samples": lambda: simulate_dataset(4, 2, seed=3),
    "classes of 1 and 2 trials beside 5": _uneven,
    "no attributes": _without_attributes,
    "no procedure layout": _without_procedures,
    "raw trials": lambda: synthetic_biotac(3, 3),
}


@pytest.fixture(scope="module", params=list(SHAPES))
def shaped(request):
    return request.param, SHAPES[request.param]()


@pytest.mark.parametrize("method", sorted(METHODS))
def test_every_method_fits_every_shape_and_answers_each_input(method, shaped):
    name, ds = shaped
    model = make_method(method, **FAST.get(method, {})).fit(ds)
    assert model.registry.known_names == list(ds.class_names), name
    raw = hasattr(ds, "trial_ids")
    answers = (
        model.recognize_trials(list(ds.trials[:3])).answers()
        if raw
        else model.recognize(ds.samples[:3])
    )
    assert len(answers) == 3
    known = set(ds.class_names)
    for a in answers:
        assert a.kind != "known" or a.class_name in known, (name, a)
        assert a.top_k and all(0.0 <= c.probability <= 1.0 for c in a.top_k), (name, a)


def test_auto_chooses_by_its_rule_where_no_probe_is_possible_and_says_so():
    """2 classes of 2 samples: no class can give the probe a trial and keep two."""
    model = make_method("auto", params={"best": FAST_BEST}).fit(simulate_dataset(2, 2, seed=3))
    chosen = model.metrics["chosen_by"]
    assert chosen["method"] == model.method == "best"
    assert chosen["reason"] == "rule" and chosen["probe"] == {}
    assert chosen["probe_classes"] == 0 and chosen["n_classes"] == 2
    assert chosen["full_size_known_acc"] is None and "no probe" in chosen["full_size_note"]


def test_auto_probes_only_the_classes_with_enough_trials():
    """The uneven shape has 4 classes of 5 trials: the probe draws those and no other."""
    model = make_method("auto", **FAST["auto"]).fit(_uneven())
    chosen = model.metrics["chosen_by"]
    assert chosen["reason"] == "probe" and chosen["probe_classes"] == 4
    assert set(chosen["probe"]) == {"prototypes", "best"}
    assert all("score" in figures for figures in chosen["probe"].values())
