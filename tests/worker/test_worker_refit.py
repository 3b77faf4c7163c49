"""worker/refit.py: a full refit in a child process under a memory limit — the same model as
a fit in process, a clear error when it is killed for memory or fails, nothing else taken
down."""

from __future__ import annotations

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.framework.registry import make_method
from worker.refit import RefitError, RefitMemoryError, default_memory_limit, fit_in_child

PARAMS = {"n_estimators": 10, "tuning_rounds": 1, "seed": 3}


@pytest.fixture(scope="module")
def dataset():
    return simulate_dataset(12, 4, seed=2)


def test_a_child_fits_the_same_model_as_this_process(dataset):
    child = fit_in_child("best", PARAMS, dataset, default_memory_limit())
    here = make_method("best", **PARAMS).fit(dataset)
    x = dataset.samples[::3]
    a, b = child.recognize_batch(x), here.recognize_batch(x)
    assert np.array_equal(a.top_index, b.top_index)
    assert np.array_equal(a.novelty_score, b.novelty_score)
    assert child.registry.known_names == here.registry.known_names


def test_a_refit_over_its_memory_limit_is_stopped_with_a_clear_error(dataset):
    with pytest.raises(RefitMemoryError, match="over its memory limit of 20 MiB"):
        fit_in_child("best", PARAMS, dataset, 20 * 2**20)
    # this process is untouched: the next refit with room succeeds
    assert fit_in_child("best", PARAMS, dataset, default_memory_limit()).registry.known_names


def test_a_refit_that_fails_says_why(dataset):
    with pytest.raises(RefitError, match="n_estimators"):
        fit_in_child("best", {**PARAMS, "n_estimators": 0}, dataset, default_memory_limit())
