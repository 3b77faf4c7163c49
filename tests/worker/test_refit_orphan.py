"""A refit's child dies with the process that started it: an API process stopped or
killed mid-refit leaves no refit running alone, its result read by nobody."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.worker.test_worker_refit import _running

ROOT = Path(__file__).resolve().parents[2]

# the stand-in for an API process: a refit in a child, the child's pid written down
PARENT = """
import sys
from app.data.simulator import simulate_dataset
from worker.refit import default_memory_limit, run_in_child
from tests.worker.test_refit_orphan import _writes_its_pid_and_sleeps
run_in_child(_writes_its_pid_and_sleeps, (sys.argv[1],), simulate_dataset(3, 2, seed=0),
             default_memory_limit(), 300)
"""


def _writes_its_pid_and_sleeps(dataset, base, pid_file: str):
    """A refit that never finishes (module-level: the spawned child imports it)."""
    Path(pid_file).write_text(str(os.getpid()))
    time.sleep(300)


@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGTERM])
def test_the_refit_child_dies_with_its_parent(tmp_path, how):
    pid_file = tmp_path / "refit.pid"
    # its temporary folder, which a killed parent cannot remove, in the test's own
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    parent = subprocess.Popen([sys.executable, "-c", PARENT, str(pid_file)], cwd=ROOT, env=env)
    try:
        for _ in range(600):  # the child imports the fitting libraries first
            if pid_file.is_file() and pid_file.read_text():
                break
            assert parent.poll() is None, "the parent ended before its refit started"
            time.sleep(0.1)
        child = int(pid_file.read_text())
        assert _running(child)
        parent.send_signal(how)
        parent.wait(30)
        for _ in range(100):
            if not _running(child):
                break
            time.sleep(0.1)
        assert not _running(child), "the refit went on without its parent"
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait()
        if pid_file.is_file() and pid_file.read_text() and _running(int(pid_file.read_text())):
            os.kill(int(pid_file.read_text()), signal.SIGKILL)
