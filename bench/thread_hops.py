"""What a worker-thread hop costs a FastAPI process: CPU per request of a bare app's
async route, sync route, and sync route with a sync generator dependency (FastAPI runs
that dependency's enter and exit in worker threads too), served as `tactile-zsl serve`
serves (uvicorn, httptools, the one-write transport) and driven by bench/load.py's client.

    .venv/bin/python -m bench.thread_hops [--clients 1] [--seconds 4]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import sys
import time

import uvloop

from app.testing.harness import free_port
from bench.load import Connection, hammer


def serve(port: int) -> None:
    import uvicorn
    from fastapi import Depends, FastAPI

    from app.server.http_protocol import CoalescingHttpToolsProtocol

    app = FastAPI()

    def one():
        yield 1

    @app.get("/async")
    async def in_loop() -> dict:
        return {"ok": 1}

    @app.get("/sync")
    def in_thread() -> dict:
        return {"ok": 1}

    @app.get("/sync-with-generator-dependency")
    def in_threads(_x: int = Depends(one)) -> dict:
        return {"ok": 1}

    uvicorn.run(
        app, host="127.0.0.1", port=port, log_level="warning", http=CoalescingHttpToolsProtocol
    )


def main() -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--clients", type=int, default=1)
    p.add_argument("--seconds", type=float, default=4)
    args = p.parse_args()
    port = free_port()
    server = multiprocessing.get_context("spawn").Process(target=serve, args=(port,))
    server.start()
    time.sleep(3)
    report = {}
    try:
        for path in ("/async", "/sync", "/sync-with-generator-dependency"):
            request = Connection.prepare("GET", path, b"", "application/json")
            out = uvloop.run(
                hammer(
                    [f"http://127.0.0.1:{port}"],
                    args.seconds,
                    args.clients,
                    request,
                    pids={"app": server.pid},
                )
            )
            report[path] = {
                "rps": out["rps"],
                "p50_ms": out["p50_ms"],
                "cpu_us_per_request": out["cpu_us_per_request"]["app"],
            }
    finally:
        server.terminate()
        server.join()
    print(json.dumps({"clients": args.clients, **report}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
