"""``tactile-zsl serve --processes 2``: several API processes on one port. Both serve,
``/metrics`` speaks for all of them, a process that dies is started again, SIGTERM
stops every one, and a process that cannot start stops the service with an error."""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from app.config import MAX_DEFAULT_PROCESSES, Settings
from app.testing.harness import STARTUP_TIMEOUT, free_port, tactile_zsl, wait_for
from app.testing.service import (
    QUICK_DATASET,
    QUICK_METHOD,
    QUICK_PARAMS,
    quick_dataset,
    unused_vectors,
)

pytestmark = pytest.mark.slow


@contextlib.contextmanager
def serving(data_dir: Path, port: int) -> Iterator[subprocess.Popen]:
    """``serve --processes 2`` on ``port``; killed afterwards if a test left it running."""
    proc = start(data_dir, port)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def two_serving(url: str, timeout: float = STARTUP_TIMEOUT, without: int | None = None) -> set[int]:
    """Wait until two processes (neither of them ``without``) serve; their pids."""
    return wait_for(
        lambda: len(p := serving_pids(url)) == 2 and without not in p and p,
        timeout,
        "2 serving processes",
    )


def start(data_dir: Path, port: int) -> subprocess.Popen:
    env = {
        **os.environ,
        "TACTILE_DATA_DIR": str(data_dir),
        "TACTILE_DATASET": QUICK_DATASET,
        "TACTILE_METHOD": QUICK_METHOD,
        "TACTILE_METHOD_PARAMS": json.dumps({QUICK_METHOD: QUICK_PARAMS}),
        "TACTILE_RATE_LIMIT": "0",
        "TACTILE_WARM_WORDS": "false",  # two processes need not load it for these checks
    }
    data_dir.mkdir(parents=True, exist_ok=True)
    log = open(data_dir / "serve.log", "wb")  # noqa: SIM115 - the process writes it
    return subprocess.Popen(
        [*tactile_zsl(), "serve", "--processes", "2", "--no-worker", "--port", str(port)],
        env=env,
        stdout=log,
        stderr=subprocess.STDOUT,
    )


def serving_pids(url: str) -> set[int]:
    """The processes behind the port, from the per-process model-version gauge."""
    text = httpx.get(f"{url}/metrics", timeout=10).text
    return {int(p) for p in re.findall(r'^tactile_active_model_version\{pid="(\d+)"\}', text, re.M)}


def test_processes_serve_together_restart_and_stop_together(tmp_path):
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    with serving(tmp_path / "data", port) as proc:
        pids = two_serving(url)

        for _ in range(30):  # a new connection each: the kernel spreads them over the processes
            assert httpx.get(f"{url}/healthz").status_code == 200
        counted = re.findall(
            r'^tactile_http_requests_total\{[^}]*route="/healthz"[^}]*\} (\S+)',
            httpx.get(f"{url}/metrics").text,
            re.M,
        )
        assert sum(float(c) for c in counted) == 30  # summed over both processes

        victim = min(pids)
        os.kill(victim, signal.SIGKILL)
        again = two_serving(url, 120, without=victim)  # the killed process is replaced
        assert httpx.get(f"{url}/readyz").status_code == 200
        refused = restore(tmp_path)  # while processes serve, the store is theirs
        assert refused.returncode == 2 and "in use by a running API process" in refused.stderr, (
            refused.stderr
        )

        # a robot waits for a job no worker will take; a stop answers it with the status then
        vector = unused_vectors(quick_dataset(), 1)[0]
        r = httpx.post(f"{url}/v1/classes", json={"name": "cup", "attribute_vector": vector})
        job_id = r.json()["job"]["id"]
        answers: list[tuple[float, httpx.Response]] = []

        def robot():
            started = time.monotonic()
            answer = httpx.get(f"{url}/v1/jobs/{job_id}", params={"wait": 20}, timeout=30)
            answers.append((time.monotonic() - started, answer))

        waiting = threading.Thread(target=robot)
        waiting.start()
        time.sleep(1.0)  # the request is waiting in one of the processes
        proc.send_signal(signal.SIGTERM)
        waiting.join(30)
        ((seconds, answer),) = answers
        assert answer.status_code == 200 and answer.json()["status"] == "queued"
        assert seconds < 15  # answered at the stop, not after its 20 s
        assert proc.wait(60) == 0
        for pid in again:
            with pytest.raises(ProcessLookupError):
                os.kill(pid, 0)
    # stopped, the store can be restored; running, it could not (checked above)
    assert restore(tmp_path).returncode == 0


def restore(tmp_path: Path) -> subprocess.CompletedProcess:
    """``tactile-zsl store restore --replace`` of a backup of the store in tmp_path/data."""
    env = {**os.environ, "TACTILE_DATA_DIR": str(tmp_path / "data")}
    backup = tmp_path / "backup.db"
    if not backup.exists():
        subprocess.run(
            [*tactile_zsl(), "store", "backup", str(backup)],
            env=env,
            check=True,
            capture_output=True,
        )
    return subprocess.run(
        [*tactile_zsl(), "store", "restore", str(backup), "--replace"],
        env=env,
        capture_output=True,
        text=True,
    )


def test_a_process_that_cannot_start_stops_the_service(tmp_path):
    with socket.socket() as taken:  # listening without SO_REUSEPORT: nobody else may bind
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        with serving(tmp_path / "data", taken.getsockname()[1]) as proc:
            assert proc.wait(STARTUP_TIMEOUT) == 1
    assert "before it served" in (tmp_path / "data" / "serve.log").read_text()


def test_the_default_is_one_process_per_core_within_bounds():
    default = Settings().api_processes
    assert 1 <= default <= MAX_DEFAULT_PROCESSES
    assert default <= (
        len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    )
    assert Settings(processes=3).api_processes == 3


def test_the_processes_stop_when_the_supervisor_is_killed(tmp_path):
    port = free_port()
    with serving(tmp_path / "data", port) as proc:
        pids = two_serving(f"http://127.0.0.1:{port}")
        proc.kill()  # SIGKILL: the supervisor cannot stop them itself
        proc.wait()

        def gone() -> bool:
            for pid in pids:
                try:
                    os.kill(pid, 0)
                    return False
                except ProcessLookupError:
                    pass
            return True

        wait_for(gone, 60, "the API processes to stop")
