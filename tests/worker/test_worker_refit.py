"""worker/refit.py: a full refit in a child process under a memory limit — the same model as
a fit in process, a clear error when it is killed for memory or fails, nothing else taken
down."""

from __future__ import annotations

import dataclasses
import os

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.framework.registry import make_method
from worker.refit import (
    RefitError,
    RefitMemoryError,
    cgroup_memory_limit,
    default_memory_limit,
    fit_in_child,
)

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


def test_a_refit_that_grows_past_its_memory_limit_is_stopped_with_a_clear_error(dataset):
    """The kernel refuses the child's allocations past the limit (RLIMIT_DATA), however
    briefly it would have held them. Under 1,000 MiB the paper's method fits on flat
    samples (the child's imports take ~250 MB); with a hidden layer of 100,000 units its
    network grows by 384 MB of weights and as much again of gradients while it trains, and
    the fit is stopped with a reason that names the limit and the refused allocation."""
    limit = 1000 * 2**20
    flat = dataclasses.replace(dataset, samples=dataset.samples.reshape(len(dataset.samples), -1))
    quick = {f"{step}_epochs": 1 for step in ("encoder", "alg1", "alg2", "fc_z")}
    quick["finetune_steps"] = 1
    assert fit_in_child("paper", quick, flat, limit).registry.known_names
    with pytest.raises(RefitMemoryError, match="over its memory limit of 1000 MiB") as stopped:
        fit_in_child("paper", {**quick, "mlp_hidden": 100_000}, flat, limit)
    assert "can't allocate memory" in str(stopped.value)


def test_a_refit_that_fails_says_why(dataset):
    with pytest.raises(RefitError, match="n_estimators"):
        fit_in_child("best", {**PARAMS, "n_estimators": 0}, dataset, default_memory_limit())


def test_the_default_limit_is_half_of_the_containers_memory_where_a_cgroup_sets_one(tmp_path):
    """cgroup v2: the smallest ``memory.max`` from this process's cgroup up to the root
    ("max" sets none); v1's ``memory.limit_in_bytes`` where the memory controller is
    mounted the old way; none: half of the machine's memory."""
    physical = default_memory_limit(tmp_path / "none", tmp_path / "none")
    v2 = tmp_path / "v2"
    (v2 / "system.slice" / "app.scope").mkdir(parents=True)
    (v2 / "memory.max").write_text("max\n")
    (v2 / "system.slice" / "memory.max").write_text(f"{3 * 2**30}\n")
    (v2 / "system.slice" / "app.scope" / "memory.max").write_text("max\n")
    proc = tmp_path / "cgroup"
    proc.write_text("0::/system.slice/app.scope\n")
    assert cgroup_memory_limit(v2, proc) == 3 * 2**30
    assert default_memory_limit(v2, proc) == min(3 * 2**30 // 2, physical)
    (v2 / "system.slice" / "memory.max").write_text("max\n")
    assert cgroup_memory_limit(v2, proc) is None
    assert default_memory_limit(v2, proc) == physical

    v1 = tmp_path / "v1"
    (v1 / "memory" / "docker" / "abc").mkdir(parents=True)
    (v1 / "memory" / "memory.limit_in_bytes").write_text("9223372036854771712\n")
    (v1 / "memory" / "docker" / "abc" / "memory.limit_in_bytes").write_text(f"{2**30}\n")
    proc.write_text("5:cpu,cpuacct:/docker/abc\n4:memory:/docker/abc\n0::/\n")
    assert cgroup_memory_limit(v1, proc) == 2**30
    assert physical == os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
