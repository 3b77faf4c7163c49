"""``tactile-zsl serve`` stops cleanly: after SIGTERM to it (a service manager's stop) or
SIGINT to its whole process group (Ctrl-C), every API process leaves through the
interpreter's exit, so the named semaphores they made are unlinked and the resource
tracker has no "leaked semaphore" to report on the way out."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import threading
import time

import httpx
import pytest

from app.testing.harness import STARTUP_TIMEOUT, free_port, tactile_zsl, wait_for
from app.testing.service import QUICK_DATASET, QUICK_METHOD, QUICK_PARAMS

pytestmark = pytest.mark.slow

WARMED = "sentence-embedding model loaded"


@pytest.mark.parametrize("how", ["SIGTERM to serve", "SIGINT to its group"])
def test_a_stop_leaves_no_leaked_semaphore(tmp_path, how):
    port = free_port()
    env = {
        **os.environ,
        "TACTILE_DATA_DIR": str(tmp_path / "data"),
        "TACTILE_DATASET": QUICK_DATASET,
        "TACTILE_METHOD": QUICK_METHOD,
        "TACTILE_METHOD_PARAMS": json.dumps({QUICK_METHOD: QUICK_PARAMS}),
        # each process reads a warm-up text once ready: a progress bar, whose
        # multiprocessing lock is a named semaphore in a spawned process
        "TACTILE_WARM_WORDS": "true",
    }
    proc = subprocess.Popen(
        [*tactile_zsl(), "serve", "--processes", "2", "--no-worker", "--port", str(port)],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        start_new_session=True,  # a group of its own, as a terminal's job is
    )
    lines: list[str] = []
    # read to the end: the pipe closes once serve, its processes and their resource
    # tracker, which writes the warning as it exits, have all gone
    reader = threading.Thread(
        target=lambda: lines.extend(line.decode(errors="replace") for line in proc.stdout)
    )
    reader.start()
    try:
        url = f"http://127.0.0.1:{port}"
        wait_for(lambda: _ready(url), STARTUP_TIMEOUT, "serve")
        wait_for(lambda: sum(WARMED in line for line in lines) == 2, 180, "both warm-ups")
        time.sleep(0.5)
        if how.startswith("SIGTERM"):
            proc.send_signal(signal.SIGTERM)
        else:
            os.killpg(proc.pid, signal.SIGINT)
        assert proc.wait(90) == 0
        reader.join(60)
        assert not reader.is_alive(), "something still holds serve's output open"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    output = "".join(lines)
    assert "leaked semaphore" not in output and "resource_tracker" not in output, output[-3000:]
    assert "Traceback" not in output, output[-3000:]


def _ready(url: str) -> bool:
    try:
        return httpx.get(f"{url}/readyz", timeout=5).status_code == 200
    except httpx.TransportError:
        return False
