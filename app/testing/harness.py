"""Real ``tactile-zsl serve --no-worker`` and ``tactile-zsl worker`` processes on one store,
for the reliability tests and the bench/ scripts: start, SIGKILL, restart, inspect."""

from __future__ import annotations

import contextlib
import json
import os
import random
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import httpx

from app.testing.service import QUICK_DATASET, QUICK_METHOD, QUICK_PARAMS

STARTUP_TIMEOUT = 420  # the first start trains the (small) base model


KEEP_VERSIONS = 3


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def tactile_zsl() -> list[str]:
    script = Path(sys.executable).with_name("tactile-zsl")
    return [str(script)] if script.exists() else [sys.executable, "-m", "app.cli"]


def wait_for(condition, timeout: float, what: str):
    """Poll ``condition()`` until it returns something true (returned), a refused
    connection counting as not yet; AssertionError after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if value := condition():
                return value
        except httpx.TransportError:
            pass
        time.sleep(0.2)
    raise AssertionError(f"timed out waiting for {what}")


@dataclass
class Proc:
    name: str  # api-0, worker-1, ...
    args: list[str]
    port: int | None = None
    popen: subprocess.Popen | None = None
    starts: int = 0

    @property
    def alive(self) -> bool:
        return self.popen is not None and self.popen.poll() is None


@dataclass
class Cluster:
    """``n_api`` API processes (each on its own port) and ``n_workers`` workers."""

    data_dir: Path
    database_url: str = ""
    n_api: int = 1
    n_workers: int = 1
    extra_env: dict[str, str] = field(default_factory=dict)
    embedded_worker: bool = False  # API processes run the worker as a thread (plain `serve`)
    # processes behind each API port; 1, so that a SIGKILL stops all of an API's work
    processes: int = 1
    procs: list[Proc] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.data_dir.mkdir(parents=True, exist_ok=True)
        self.env = {
            **os.environ,
            "TACTILE_DATA_DIR": str(self.data_dir),
            "TACTILE_DATABASE_URL": self.database_url,
            "TACTILE_DATASET": QUICK_DATASET,
            "TACTILE_METHOD": QUICK_METHOD,
            "TACTILE_METHOD_PARAMS": json.dumps({QUICK_METHOD: QUICK_PARAMS}),
            "TACTILE_MODEL_POLL_SECONDS": "0.2",
            "TACTILE_WORKER_POLL_SECONDS": "0.1",
            "TACTILE_LEASE_SECONDS": "10",
            "TACTILE_RATE_LIMIT": "0",
            # the worker prunes old versions every round, so crashes and swaps meet pruning
            "TACTILE_KEEP_VERSIONS": str(KEEP_VERSIONS),
            **self.extra_env,
        }
        for i in range(self.n_api):
            port = free_port()
            serve = ["serve", "--port", str(port), "--processes", str(self.processes)]
            serve += [] if self.embedded_worker else ["--no-worker"]
            self.procs.append(Proc(f"api-{i}", serve, port))
        for i in range(self.n_workers):
            self.procs.append(Proc(f"worker-{i}", ["worker"]))

    @property
    def urls(self) -> list[str]:
        return [f"http://127.0.0.1:{p.port}" for p in self.procs if p.port]

    @property
    def apis(self) -> list[Proc]:
        return [p for p in self.procs if p.port]

    @property
    def workers(self) -> list[Proc]:
        return [p for p in self.procs if not p.port]

    def start(self, proc: Proc | None = None) -> None:
        for p in [proc] if proc else self.procs:
            if p.alive:
                continue
            log = open(self.data_dir / f"{p.name}-{p.starts}.log", "wb")  # noqa: SIM115
            p.starts += 1
            p.popen = subprocess.Popen(
                [*tactile_zsl(), *p.args],
                env=self.env,
                cwd=self.data_dir,
                stdout=log,
                stderr=subprocess.STDOUT,
            )

    def kill(self, proc: Proc) -> None:
        """SIGKILL: no cleanup, no lease release, whatever was in flight is cut."""
        if proc.alive:
            proc.popen.send_signal(signal.SIGKILL)
            proc.popen.wait()

    def kill_random(self, rng: random.Random) -> Proc:
        proc = rng.choice(self.procs)
        self.kill(proc)
        return proc

    def stop(self) -> None:
        for p in self.procs:
            if p.alive:
                p.popen.send_signal(signal.SIGTERM)
        for p in self.procs:
            if p.popen is None:
                continue
            try:
                p.popen.wait(60)
            except subprocess.TimeoutExpired:
                p.popen.kill()
                p.popen.wait()

    def wait_ready(self, timeout: float = STARTUP_TIMEOUT) -> None:
        deadline = time.monotonic() + timeout
        pending = list(self.urls)
        while pending and time.monotonic() < deadline:
            for url in list(pending):
                try:
                    if httpx.get(f"{url}/readyz", timeout=2).status_code == 200:
                        pending.remove(url)
                except httpx.TransportError:
                    pass
            for p in self.procs:
                assert p.popen is None or p.popen.poll() is None, (
                    f"{p.name} exited with {p.popen.returncode}:\n{self.logs()}"
                )
            time.sleep(0.3)
        assert not pending, f"not ready after {timeout}s: {pending}\n{self.logs()}"

    def logs(self, tail: int = 3000) -> str:
        return "\n".join(
            f"--- {f.name}\n{f.read_text(errors='replace')[-tail:]}"
            for f in sorted(self.data_dir.glob("*.log"))
        )

    @property
    def sqlalchemy_url(self) -> str:
        return self.database_url or f"sqlite:///{(self.data_dir / 'tactile.db').resolve()}"


@contextlib.contextmanager
def serving(data_dir: Path, env: dict[str, str]) -> Iterator[str]:
    """A real ``tactile-zsl serve`` (its embedded worker too) on a free port, with ``env``
    (``TACTILE_DATASET``, ...) over this process's environment; yields its URL."""
    port = free_port()
    env = {
        **os.environ,
        "TACTILE_DATA_DIR": str(data_dir),
        "TACTILE_WORKER_POLL_SECONDS": "0.1",
        "TACTILE_MODEL_POLL_SECONDS": "0.2",
        **env,
    }
    with open(data_dir / "serve.log", "wb") as log:
        proc = subprocess.Popen(
            [*tactile_zsl(), "serve", "--processes", "1", "--port", str(port)],
            env=env,
            stdout=log,
            stderr=subprocess.STDOUT,
        )
    url = f"http://127.0.0.1:{port}"

    def ready() -> bool:
        if proc.poll() is not None:
            tail = (data_dir / "serve.log").read_text(errors="replace")[-3000:]
            raise AssertionError(f"serve exited with {proc.returncode}:\n{tail}")
        return httpx.get(f"{url}/readyz").status_code == 200

    try:
        wait_for(ready, STARTUP_TIMEOUT, f"serve (its log: {data_dir / 'serve.log'})")
        yield url
    finally:
        proc.terminate()
        proc.wait(60)


def wait_jobs_settled(url: str, timeout: float) -> dict[str, int]:
    """Poll the store until no job is queued or running; returns the status counts."""
    from app.store import repo
    from app.store.db import make_engine, make_sessionmaker

    engine = make_engine(url)
    sessions = make_sessionmaker(engine)
    deadline = time.monotonic() + timeout
    try:
        while True:
            with sessions() as s:
                counts = repo.jobs_by_status(s)
            if not counts.get("queued") and not counts.get("running"):
                return counts
            if time.monotonic() > deadline:
                return counts
            time.sleep(0.3)
    finally:
        engine.dispose()
