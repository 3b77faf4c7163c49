"""``tactile-zsl serve`` with several API processes on one port.

Each process binds a socket of its own with ``SO_REUSEPORT``, so the kernel spreads new
connections over the processes by address hash; with one shared listening socket (what
uvicorn's ``workers`` does) a burst of connections went to whichever process woke first.
The parent only supervises: it starts a process again when one dies, gives up when one
dies before it served (it would again: a port taken, a bad setting), and stops them all
on SIGTERM or SIGINT.
Prometheus metrics live in files the processes share (prometheus_client's multiprocess
mode), so ``/metrics`` answers for all of them whichever process is asked.
"""

from __future__ import annotations

import ctypes
import logging
import multiprocessing
import os
import shutil
import signal
import socket
import tempfile
import threading
from typing import Any

import uvicorn
from prometheus_client import multiprocess

from app.server.logs import configure_logging

log = logging.getLogger(__name__)

PR_SET_PDEATHSIG = 1  # linux/prctl.h


def supported() -> bool:
    return hasattr(socket, "SO_REUSEPORT")


def free_port(host: str) -> int:
    with socket.socket(_family(host)) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


class AnnouncingServer(uvicorn.Server):
    """A uvicorn server that logs ``ready`` once its app has started (the model loaded) and
    its socket listens: the moment ``/readyz`` answers ready, not before the model loads."""

    def __init__(self, config: uvicorn.Config, ready: str) -> None:
        super().__init__(config)
        self.ready = ready

    async def startup(self, sockets: list[socket.socket] | None = None) -> None:
        await super().startup(sockets)
        if self.started:
            log.info("%s", self.ready)


def serve(overrides: dict[str, Any], n: int, server: dict[str, Any], ready: str = "") -> int:
    """Run ``n`` API processes (``Settings(**overrides)`` each, uvicorn options ``server``)
    until SIGTERM or SIGINT; the exit status. ``ready`` is logged once every process
    serves (each has loaded its model and listens)."""
    metrics_dir = tempfile.mkdtemp(prefix="tactile-metrics-")
    os.environ["PROMETHEUS_MULTIPROC_DIR"] = metrics_dir  # the spawned processes inherit it
    context = multiprocessing.get_context("spawn")  # fresh interpreters: no forked threads or locks
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    procs: dict[
        int, tuple[multiprocessing.Process, Any]
    ] = {}  # index -> (process, its "serving" event)

    def start(index: int) -> None:
        serving = context.Event()
        proc = context.Process(
            target=_run_one, args=(overrides, server, index, serving), name=f"tactile-api-{index}"
        )
        proc.start()
        procs[index] = (proc, serving)

    status = 0
    announced = False
    try:
        for index in range(n):
            start(index)
        while not stop.wait(0.1 if not announced else 0.5):
            if not announced and all(serving.is_set() for _, serving in procs.values()):
                announced = True
                if ready:
                    log.info("%s", ready)
            for index, (proc, serving) in list(procs.items()):
                if proc.is_alive():
                    continue
                if not serving.is_set():
                    log.error(
                        "API process %d exited (%s) before it served; stopping",
                        index,
                        proc.exitcode,
                    )
                    status = 1
                    stop.set()
                    break
                log.warning(
                    "API process %d (pid %s) exited (%s); starting it again",
                    index,
                    proc.pid,
                    proc.exitcode,
                )
                multiprocess.mark_process_dead(proc.pid)  # drop its per-process gauges
                start(index)
    finally:
        for proc, _ in procs.values():
            if proc.is_alive():
                proc.terminate()  # SIGTERM: uvicorn finishes the requests in flight
        for proc, _ in procs.values():
            proc.join(30)
            if proc.is_alive():
                proc.kill()
                proc.join()
        shutil.rmtree(metrics_dir, ignore_errors=True)
    return status


def _family(host: str) -> socket.AddressFamily:
    return socket.AF_INET6 if ":" in host else socket.AF_INET


def _stop_with_parent() -> None:
    """Ask Linux for SIGTERM when the supervisor dies, even by SIGKILL: an API process left
    behind would keep the port and serve with nobody to restart or stop it."""
    parent = os.getppid()
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):  # not Linux: the supervisor's SIGTERM is what stops us
        return
    if os.getppid() != parent:  # it died before we asked
        os.kill(os.getpid(), signal.SIGTERM)


def _exit_cleanly(signum: int, frame: Any) -> None:
    """Stop by leaving the interpreter, not by the signal's default action. uvicorn stops
    gracefully on SIGTERM or SIGINT, then raises the signal again with the handler found
    before it ran: under the default one the process dies without its exit functions, and
    the named semaphores it made (a spawned process's ``multiprocessing`` locks: tqdm's, once
    a progress bar is drawn) are never unlinked, so the resource tracker reports them as
    leaked when ``serve`` stops."""
    raise SystemExit(0)


def _run_one(overrides: dict[str, Any], server: dict[str, Any], index: int, serving: Any) -> None:
    class Server(uvicorn.Server):
        async def startup(self, sockets: list[socket.socket] | None = None) -> None:
            await super().startup(sockets)
            if self.started:
                serving.set()

        async def shutdown(self, sockets: list[socket.socket] | None = None) -> None:
            # uvicorn waits for open requests before the app's own shutdown runs: robots
            # waiting for their jobs answer first, or they would hold it for up to 20 s
            app.state.service.job_watch.release_all()
            await super().shutdown(sockets)

    from app.api.main import create_app
    from app.config import Settings

    configure_logging()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, _exit_cleanly)
    _stop_with_parent()
    settings = Settings(**overrides)
    sock = socket.socket(_family(settings.host), socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
    sock.bind((settings.host, settings.port))
    app = create_app(settings, process_index=index)
    Server(uvicorn.Config(app, **server)).run(sockets=[sock])
