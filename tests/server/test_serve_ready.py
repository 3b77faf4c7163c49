"""A real ``tactile-zsl serve``: it says "serving on" when ``/readyz`` answers ready (not
before the model has loaded), loads the sentence-embedding model in the background once
ready, and its log, a file, holds no progress bar."""

from __future__ import annotations

import json
import os
import subprocess
import time
from pathlib import Path

import httpx
import pytest

from app.testing.harness import STARTUP_TIMEOUT, free_port, tactile_zsl, wait_for
from app.testing.service import QUICK_DATASET, QUICK_METHOD, QUICK_PARAMS

pytestmark = pytest.mark.slow

READY = "serving on http://"
WARM = "sentence-embedding model loaded"


def start(data_dir: Path, port: int, processes: int) -> subprocess.Popen:
    env = {
        **os.environ,
        "TACTILE_DATA_DIR": str(data_dir),
        "TACTILE_DATASET": QUICK_DATASET,
        "TACTILE_METHOD": QUICK_METHOD,
        "TACTILE_METHOD_PARAMS": json.dumps({QUICK_METHOD: QUICK_PARAMS}),
        "TACTILE_RATE_LIMIT": "0",
        "TACTILE_WARM_WORDS": "true",
    }
    data_dir.mkdir(parents=True, exist_ok=True)
    log = open(data_dir / "serve.log", "wb")  # noqa: SIM115 - the process writes it
    args = ["serve", "--processes", str(processes), "--no-worker", "--port", str(port)]
    return subprocess.Popen([*tactile_zsl(), *args], env=env, stdout=log, stderr=subprocess.STDOUT)


def readyz(url: str) -> int | None:
    """/readyz's status on a new connection (so that with several processes the kernel may
    pick any of them); None while nothing listens."""
    try:
        return httpx.get(f"{url}/readyz", timeout=10).status_code
    except httpx.TransportError:
        return None


@pytest.mark.parametrize("processes", [1, 2])
def test_serving_on_is_said_when_readyz_says_ready(tmp_path, processes):
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    log = tmp_path / "data" / "serve.log"
    proc = start(tmp_path / "data", port, processes)
    try:
        seen: list[int | None] = []
        deadline = time.monotonic() + STARTUP_TIMEOUT
        while READY not in log.read_text() and time.monotonic() < deadline:
            assert proc.poll() is None, log.read_text()
            seen.append(readyz(url))
            time.sleep(0.1)
        assert READY in log.read_text(), log.read_text()
        # once it is said, every process answers ready
        assert [readyz(url) for _ in range(8)] == [200] * 8, log.read_text()
        if processes == 1:  # of several, one may answer ready before the others are
            assert 200 not in seen[:-3]  # not ready long before it was said (a poll's slack)
        text = log.read_text()
        assert f"with {processes} API process" in text and "/docs" in text
        # the log is a file: no progress bar redraws in it
        assert "\r" not in text and "it/s]" not in text, text
        if processes == 1:
            warm_before_any_description(url, log)
    finally:
        proc.terminate()
        proc.wait(60)


def warm_before_any_description(url: str, log: Path) -> None:
    """The sentence-embedding model loads after "serving on" without a request, before the
    first description, which the loaded model then reads."""
    wait_for(lambda: WARM in log.read_text(), 120, "the sentence-embedding model loaded")
    text = log.read_text()
    assert text.index(READY) < text.index(WARM)
    assert "\r" not in text and "Loading weights" not in text, text  # its bars neither
    r = httpx.post(f"{url}/v1/attributes/interpret", json={"text": "soft and squishy"}, timeout=30)
    assert r.status_code == 200 and r.json()["values"], r.text
