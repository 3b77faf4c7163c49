"""worker/refit.py: a full refit (or an attribute rebuild) in a child process under memory
and time limits — the same model as in process, a clear error when it is stopped for memory
or time or fails, nothing else taken down."""

from __future__ import annotations

import dataclasses
import os
import re
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.framework import bundle
from app.framework.registry import make_method
from tests.service_fixtures import add_sample, job, refit_stopped
from worker.refit import (
    RefitError,
    RefitMemoryError,
    RefitTimeoutError,
    attributes_in_child,
    cgroup_memory_limit,
    default_memory_limit,
    fit_in_child,
    run_in_child,
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
    # torch's allocator refusing the weights, or an import after them refused its memory
    assert re.search(r"can't allocate memory|\(MemoryError: in ", str(stopped.value))


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


# Tasks for ``run_in_child``: module-level, so that the spawned child imports them.


def _sleeps_with_a_child(dataset, base, pid_file: str):
    """Starts a process of its own, then never finishes."""
    started = subprocess.Popen(["sleep", "600"])
    Path(pid_file).write_text(str(started.pid))
    time.sleep(600)


def _grows_a_faiss_index(dataset, base):
    """Adds vectors to a faiss index until faiss's allocation fails (std::bad_alloc)."""
    import faiss

    index = faiss.IndexFlatL2(64)
    block = np.ones((16384, 64), np.float32)
    while True:
        index.add(block)


def _allocates_with_numpy(dataset, base):
    return np.ones((2**30,), np.float32)  # 4 GiB


def _aborts_on_bad_alloc(dataset, base):
    """Ends as a C++ library ends a process when its std::bad_alloc escapes where nothing
    catches it (an OpenMP region): libstdc++'s last words on stderr, then SIGABRT."""
    os.write(2, b"terminate called after throwing an instance of 'std::bad_alloc'\n")
    os.write(2, b"  what():  std::bad_alloc\n")
    os.abort()


def _memory_error_escapes(dataset, base):
    """Ends as a child does whose MemoryError escaped before its report was written (under
    a limit below what its imports hold, writing the report needs memory too): Python's
    traceback on stderr, then exit code 1."""
    os.write(2, b"Traceback (most recent call last):\n")
    os.write(2, b'  File "worker/refit.py", line 304, in _child\n')
    os.write(2, b"MemoryError\n")
    os._exit(1)


def _is_killed(dataset, base):
    """Ends as the kernel's out-of-memory killer ends a process."""
    os.kill(os.getpid(), signal.SIGKILL)


def _running(pid: int) -> bool:
    """Whether the process lives (a zombie, which a container's init may leave, does not)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


def test_a_refit_past_its_time_limit_is_killed_with_what_it_started(dataset, tmp_path):
    """Past ``seconds`` the child is killed with its process group (what it started, here a
    ``sleep``, dies with it), and the error names the limit and the setting."""
    pid_file = tmp_path / "pid"
    with pytest.raises(RefitTimeoutError, match="time limit of 20 s") as stopped:
        run_in_child(_sleeps_with_a_child, (str(pid_file),), dataset, default_memory_limit(), 20)
    assert "Raise TACTILE_REFIT_SECONDS (0: no limit)" in str(stopped.value)
    started = int(pid_file.read_text())
    for _ in range(100):  # killed at once; reaped by init as soon as it gets to it
        if not _running(started):
            break
        time.sleep(0.1)
    assert not _running(started)


def test_faiss_std_bad_alloc_is_a_memory_stop(dataset):
    """faiss allocates with C++'s ``new``: under the limit it throws std::bad_alloc, which
    stops the refit for memory, not as a failure of another kind."""
    limit = 1000 * 2**20
    with pytest.raises(RefitMemoryError, match="memory limit of 1000 MiB") as stopped:
        run_in_child(_grows_a_faiss_index, (), dataset, limit)
    assert "bad_alloc" in str(stopped.value)
    assert "Raise TACTILE_REFIT_MEMORY_LIMIT_MB" in str(stopped.value)


def test_numpys_memory_error_a_kill_and_an_abort_for_memory_are_memory_stops(dataset):
    limit = 1000 * 2**20
    with pytest.raises(RefitMemoryError, match="Unable to allocate 4.00 GiB"):
        run_in_child(_allocates_with_numpy, (), dataset, limit)
    with pytest.raises(RefitMemoryError, match="SIGKILL, as the kernel's out-of-memory killer"):
        run_in_child(_is_killed, (), dataset, limit)
    with pytest.raises(RefitMemoryError, match=r"instance of 'std::bad_alloc'; ended by SIGABRT"):
        run_in_child(_aborts_on_bad_alloc, (), dataset, limit)
    with pytest.raises(RefitMemoryError, match=r"\(MemoryError; exit code 1\)"):
        run_in_child(_memory_error_escapes, (), dataset, limit)


def test_an_attribute_refit_in_a_child_is_the_one_in_process_sharing_the_rest(dataset):
    """``attributes_in_child`` gives the model ``with_attributes`` gives here, and its
    arrays that the attribute refit leaves as they were are the base model's own."""
    base = make_method("best", **PARAMS).fit(dataset)
    rng = np.random.default_rng(0)
    wider = dataclasses.replace(
        dataset,
        attribute_names=(*dataset.attribute_names, "sticky"),
        class_attributes=np.concatenate(
            [dataset.class_attributes, rng.integers(0, 2, (dataset.n_classes, 1))], axis=1
        ).astype(np.float32),
    )
    child = attributes_in_child(base, wider, default_memory_limit())
    here = base.with_attributes(wider)
    x = dataset.samples[::3]
    assert child.registry.attribute_names == here.registry.attribute_names
    assert np.array_equal(child.attribute_proba(x), here.attribute_proba(x))
    assert np.array_equal(child.recognize_batch(x).top_index, here.recognize_batch(x).top_index)
    _, mine = bundle._contents(base)
    _, new = bundle._contents(child)
    assert np.shares_memory(new["known/reference"], mine["known/reference"])
    assert not np.shares_memory(new["attributes/weights"], mine["attributes/weights"])


def test_a_promotion_whose_refit_runs_out_of_time_fails_clearly_and_the_model_stays(
    client, app, worker, dataset
):
    """A refit past ``refit_seconds`` (here a real promotion's fit, stopped after 2 s, less
    than the child takes to start) fails its jobs with that reason; the active model
    answers throughout, the class stays novel, and with time enough it is promoted."""
    settings = app.state.service.settings
    cid, active, last, answers = refit_stopped(client, app, worker, dataset, refit_seconds=2)
    assert set(answers) == {(200, active)}
    failed = job(client, last["job"]["id"])
    assert failed["status"] == "failed"
    assert "RefitTimeoutError" in failed["error"] and "time limit of 2 s" in failed["error"]
    assert client.get("/v1/models/active").json()["version"] == active
    assert client.get(f"/v1/classes/{cid}").json()["kind"] == "novel"
    settings.refit_seconds = 0  # no limit
    add_sample(client, cid, dataset.samples[2] + 0.01)
    assert worker.run_once() == 1
    assert client.get(f"/v1/classes/{cid}").json()["kind"] == "known"
