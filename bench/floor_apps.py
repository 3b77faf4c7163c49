"""The servers ``bench/side_by_side.py`` sets beside the service, and how they are started.

- ``floor_app``: the framework's floor, a bare FastAPI app whose ``POST /v1/recognize``
  parses the body into a float32 array (orjson + numpy) and answers a fixed small JSON;
- ``sklearn_app``: a first scikit-learn service, the same parsing, and
  ``ExtraTreesClassifier(n_estimators=100).predict_proba`` of a forest fitted at start-up
  on the simulator's dataset (flattened samples).

Both on the service's stack (uvicorn, uvloop, httptools; no access log), on 127.0.0.1, with
``GET /healthz``. One server, ``--workers`` processes each with its own SO_REUSEPORT socket
on the port (as ``tactile-zsl serve --processes N`` runs its API processes):

    .venv/bin/python -m bench.floor_apps {floor,sklearn} --port PORT [--workers N]

``app_server`` starts one in a process group of its own and stops the whole group.
"""

from __future__ import annotations

# Only what the floor and the scikit-learn app need is imported at module level: uvicorn
# imports this module in the servers' own processes, and the floor should carry nothing
# else (a larger heap makes every garbage collection, and so the floor's p99, longer).
# What only the bench process uses (httpx, the test harness, argparse) is imported inside
# the functions that use it.
import contextlib
import multiprocessing
import multiprocessing.connection
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import orjson
from fastapi import FastAPI, Request, Response

ROOT = Path(__file__).resolve().parents[1]
HOST = "127.0.0.1"
STACK = {"loop": "uvloop", "http": "httptools", "access_log": False, "log_level": "warning"}
START_TIMEOUT_S = 420  # the service's first start trains the base model

FLOOR_ANSWER = orjson.dumps(
    {"results": [{"label": "object-00", "probability": 1.0, "is_novel": False}]}
)


def parse_samples(body: bytes) -> np.ndarray:
    """The body ``{"samples": [...]}`` as a float32 array: what both apps do with it."""
    return np.asarray(orjson.loads(body)["samples"], dtype=np.float32)


def _healthy_app() -> FastAPI:
    """A FastAPI app with the ``/healthz`` route the bench waits on before measuring."""
    app = FastAPI()

    @app.get("/healthz")
    async def healthz() -> Response:
        return Response(b'{"status":"ok"}', media_type="application/json")

    return app


def floor_app() -> FastAPI:
    """The framework's floor: FastAPI reading the body, parsing it, answering fixed bytes."""
    app = _healthy_app()

    @app.post("/v1/recognize")
    async def recognize(request: Request) -> Response:
        parse_samples(await request.body())
        return Response(FLOOR_ANSWER, media_type="application/json")

    return app


def sklearn_app() -> FastAPI:
    """What a user writes first: a scikit-learn forest fitted at start-up, answering
    ``predict_proba`` of each request's samples."""
    from sklearn.ensemble import ExtraTreesClassifier

    from app.data.simulator import simulate_dataset

    data = simulate_dataset()
    forest = ExtraTreesClassifier(n_estimators=100, random_state=0)
    forest.fit(data.samples.reshape(len(data.samples), -1), data.labels)
    names = np.asarray(data.class_names)[forest.classes_]
    app = _healthy_app()

    @app.post("/v1/recognize")
    async def recognize(request: Request) -> Response:
        x = parse_samples(await request.body())
        proba = forest.predict_proba(x.reshape(len(x), -1))
        best = proba.argmax(axis=1)
        results = [
            {"label": str(names[b]), "probability": float(p[b])}
            for b, p in zip(best, proba, strict=True)
        ]
        return Response(orjson.dumps({"results": results}), media_type="application/json")

    return app


APPS = {"floor": "floor_app", "sklearn": "sklearn_app"}


# ----------------------------------------------------------------- in the server's process


def serve(kind: str, port: int, workers: int) -> int:
    """``workers`` processes each with its own SO_REUSEPORT socket on ``port``, as
    ``tactile-zsl serve --processes N`` spreads connections over its API processes (with
    uvicorn's ``workers``, one inherited socket, one process could accept all of them)."""
    if workers == 1:
        serve_one(kind, port)
        return 0
    context = multiprocessing.get_context("spawn")
    procs = [context.Process(target=serve_one, args=(kind, port)) for _ in range(workers)]
    for proc in procs:
        proc.start()
    # the process group's SIGTERM reaches the workers too: wait for them to finish
    signal.signal(signal.SIGTERM, lambda *_: None)
    multiprocessing.connection.wait([proc.sentinel for proc in procs])
    status = 0 if all(proc.exitcode in (0, None) for proc in procs) else 1
    for proc in procs:  # one failed or stopped: the others go too
        if proc.is_alive():
            proc.terminate()
        proc.join()
    return status


def serve_one(kind: str, port: int) -> None:
    import uvicorn

    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
    sock.bind((HOST, port))
    config = uvicorn.Config(f"bench.floor_apps:{APPS[kind]}", factory=True, **STACK)
    uvicorn.Server(config).run(sockets=[sock])


# ----------------------------------------------------------------- in the bench's process


@contextlib.contextmanager
def app_server(kind: str, workers: int, log_dir: Path):
    """One of this module's apps under uvicorn in a process of its own (``workers``
    processes on its port); yields (url, pid). Stopped on exit, whatever happened."""
    import httpx

    from app.testing.harness import free_port

    port = free_port()
    log = open(log_dir / f"{kind}-{workers}.log", "wb")  # noqa: SIM115
    cmd = [sys.executable, "-m", "bench.floor_apps", kind, "--port", str(port)]
    proc = subprocess.Popen(
        [*cmd, "--workers", str(workers)],
        cwd=ROOT,
        stdout=log,
        stderr=subprocess.STDOUT,
        start_new_session=True,  # its own process group, so that its workers go with it
    )
    url = f"http://{HOST}:{port}"
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while True:
            if proc.poll() is not None:
                raise RuntimeError(f"{kind} server exited with {proc.returncode}: {tail(log)}")
            with contextlib.suppress(httpx.TransportError):
                if httpx.get(f"{url}/healthz", timeout=2).status_code == 200:
                    break
            if time.monotonic() > deadline:
                raise RuntimeError(f"{kind} server not up after {START_TIMEOUT_S} s: {tail(log)}")
            time.sleep(0.2)
        yield url, proc.pid
    finally:
        stop_group(proc)
        log.close()


def stop_group(proc: subprocess.Popen) -> None:
    """SIGTERM to the process group this bench started (the server and its workers), the
    whole group SIGKILLed after 30 s."""
    if proc.poll() is not None:
        return
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(30)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def tail(log, n: int = 2000) -> str:
    log.flush()
    return Path(log.name).read_text(errors="replace")[-n:]


def main() -> int:
    import argparse

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("kind", choices=sorted(APPS), help="which app")
    p.add_argument("--port", type=int, required=True, help="the port on 127.0.0.1")
    p.add_argument("--workers", type=int, default=1, help="processes on the port (default 1)")
    args = p.parse_args()
    return serve(args.kind, args.port, args.workers)


if __name__ == "__main__":
    sys.exit(main())
