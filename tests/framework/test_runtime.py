"""Thread settings are the entry points' choice: importing a method changes none, the
choice holds for torch loaded later, and a process that never chose still fits on one
thread. Each case runs in a fresh interpreter: the settings are process-wide."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

FIT_A_SMALL_PAPER_MODEL = """
from app.data.simulator import simulate_dataset
from app.framework.paper import PaperRecognizer
ds = simulate_dataset(n_objects=6, trials_per_object=3, seed=0)
PaperRecognizer(encoder_epochs=1, alg1_epochs=1, alg2_epochs=1, fc_z_epochs=1).fit(ds)
"""

SEEN = """
import os, sys, torch
from threadpoolctl import threadpool_info
from app.framework import runtime
def seen():
    return {"chosen": runtime._threads, "torch": torch.get_num_threads(),
            "blas": sorted({p["num_threads"] for p in threadpool_info()
                            if p["user_api"] == "blas"}),
            "openblas_env": os.environ.get("OPENBLAS_NUM_THREADS")}
"""


def _run(code: str) -> dict:
    unset = ("TACTILE_TORCH_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
    env = {k: v for k, v in os.environ.items() if k not in unset}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.timeout(300)
def test_importing_methods_sets_no_threads_and_the_first_fit_gets_the_default():
    seen = _run(
        SEEN
        + """
import json
before = seen()
import app.methods.best, app.framework.paper, app.baselines.dap, app.baselines.eszsl
import app.baselines.extra_trees, app.framework.registry, app.framework.bundle
imported = seen()
"""
        + FIT_A_SMALL_PAPER_MODEL
        + """
print(json.dumps({"before": before, "imported": imported, "fitted": seen()}))
"""
    )
    assert seen["imported"] == seen["before"], seen
    assert seen["imported"]["chosen"] is None
    fitted = seen["fitted"]
    assert fitted["chosen"] == 1 and fitted["torch"] == 1 and fitted["blas"] == [1], seen
    assert fitted["openblas_env"] == "1"


@pytest.mark.timeout(300)
def test_torch_gets_the_threads_the_process_chose_when_it_loads_later():
    seen = _run(
        """
import json
from app.framework.runtime import configure_threads
configure_threads(3)  # as an entry point does (serve: its torch_threads setting), torch not loaded
"""
        + SEEN
        + FIT_A_SMALL_PAPER_MODEL
        + """
print(json.dumps(seen()))
"""
    )
    # (BLAS libraries cap their threads at the machine's cores: only torch shows the 3 here)
    assert seen["chosen"] == 3 and seen["torch"] == 3 and seen["openblas_env"] == "3", seen


@pytest.mark.timeout(300)
def test_the_cli_commands_choose_at_their_start(tmp_path):
    seen = _run(
        SEEN
        + f"""
import json
from app.cli import main
main(["recognize", "--model", {str(tmp_path / "none.bundle")!r}, "-"])  # fails: no bundle
print(json.dumps(seen()))
"""
    )
    assert seen["chosen"] == 1 and seen["blas"] == [1], seen


HEAP = """
import json, numpy as np
from app.framework import runtime
def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096
took = runtime.configure_heap() if CONFIGURE else None
large = np.ones(16 << 20, np.uint8)
del large  # a large block freed: glibc raises its threshold past 2 MiB
blocks = [np.ones(2 << 20, np.uint8) for _ in range(100)]  # 200 MiB, resident
before = rss()
del blocks[::2]  # every other one freed: none next to another, none at the heap's top
print(json.dumps({"took": took, "given_back_mib": (before - rss()) / 2**20}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator")
def test_a_fits_freed_arrays_go_back_to_the_system():
    """glibc keeps freed 2 MiB blocks resident once a larger block was freed; with
    configure_heap (what a fit calls) they have mappings of their own and go back."""
    configured = _run("CONFIGURE = True\n" + HEAP)
    default = _run("CONFIGURE = False\n" + HEAP)
    assert configured["took"] is True
    assert configured["given_back_mib"] > 80 and default["given_back_mib"] < 20, (
        configured,
        default,
    )
    seen = _run(
        "import json\nfrom app.framework import runtime\n"
        + FIT_A_SMALL_PAPER_MODEL
        + "print(json.dumps({'heap': runtime._heap}))"
    )
    assert seen["heap"] is True  # a fit configured it
