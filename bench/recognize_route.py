"""What ``POST /v1/recognize`` costs in process, against another checkout, side by side; and
a table of objects against as many single recognitions.

    .venv/bin/python -m bench.recognize_route [--against DIR] [--rounds 5] [--requests 2000]
                                              [--objects 12] [--method NAME] [--clients 1]
                                              [--no-tables] [--json OUT]

Each tree (this one, and ``--against``: another checkout, e.g. ``git worktree add
/tmp/base <commit>``) runs in a process of its own: the quick service of ``app.testing``
(the simulator, method ``best`` with the tests' quick parameters, SQLite, no rate limit),
its ASGI app called directly (no socket, no client: the route's own CPU, the fast path
included) with one-sample JSON bodies, the simulator's first sample. The two alternate,
``--requests`` requests each a round, taking turns going first; each round's ratio (this
tree over the other, CPU microseconds a request) is taken between adjacent phases, and
the median and range over ``--rounds`` are reported. ``--method NAME`` serves that method
instead, fitted with its default parameters on the embedded default's dataset (the
simulator's 60 objects), as ``tactile-zsl serve`` would; ``--clients N`` sends the requests
N at a time (``asyncio.gather``), so that they share the batcher's passes as a loaded
service's do.

Then, in this tree only, as many rounds: a table of ``--objects`` objects, one touch each
(``{"samples", "objects"}``), against ``--objects`` single-sample requests one after
the other and against one ordinary batch of as many samples, as ratios.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------ child side
def _scope(body: bytes) -> dict:
    return {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": "POST",
        "scheme": "http",
        "path": "/v1/recognize",
        "raw_path": b"/v1/recognize",
        "root_path": "",
        "query_string": b"",
        "headers": [
            (b"host", b"127.0.0.1:8000"),
            (b"content-type", b"application/json"),
            (b"content-length", str(len(body)).encode()),
        ],
        "client": ("127.0.0.1", 40000),
        "server": ("127.0.0.1", 8000),
    }


async def _call(app, body: bytes) -> bytes:
    sent: list[dict] = []

    async def receive() -> dict:
        return {"type": "http.request", "body": body, "more_body": False}

    async def send(message: dict) -> None:
        sent.append(message)

    await app(_scope(body), receive, send)
    status = sent[0]["status"]
    if status != 200:
        raise RuntimeError(f"status {status}: {sent[1].get('body', b'')[:300]!r}")
    return sent[-1]["body"]


async def _per_request(app, body: bytes, n: int, clients: int = 1) -> float:
    """Microseconds a request: the process's CPU time, every thread's (the batcher's and
    the thread pool's too), so a shared machine's waits are left out; ``clients`` at a
    time."""
    waves = max(1, n // clients)
    start = time.process_time()
    for _ in range(waves):
        if clients == 1:
            await _call(app, body)
        else:
            await asyncio.gather(*(_call(app, body) for _ in range(clients)))
    return (time.process_time() - start) / (waves * clients) * 1e6


async def _child(method: str | None, clients: int) -> None:
    """Serve measurements for the parent: one line in ('single N', 'table N K'), one
    JSON line out."""
    sys.path.insert(0, os.getcwd())  # the tree this process was started in
    import numpy as np

    from app.api.main import create_app
    from app.data.simulator import simulate_dataset
    from app.framework.registry import make_method
    from app.testing.service import BEST_PARAMS, quick_dataset, quick_settings

    if method is None:  # the tests' quick service
        dataset, method, params = quick_dataset(), "best", BEST_PARAMS
    else:  # the method as the embedded default fits it
        dataset, params = simulate_dataset(), {}
    model = make_method(method, **params).fit(dataset)
    x = dataset.samples
    # no rate limit: capacity is measured (as bench/load.py runs the service)
    settings = {"method": method, "method_params": {method: params}, "rate_limit": 0}
    with tempfile.TemporaryDirectory() as tmp:
        app = create_app(quick_settings(Path(tmp), **settings), trainer=lambda: (model, dataset))
        async with app.router.lifespan_context(app):
            one = json.dumps({"samples": [x[0].tolist()]}).encode()
            for _ in range(200):  # warm: the fast path's stack, caches, the batcher
                await _call(app, one)
            print(json.dumps({"ready": True}), flush=True)
            for line in sys.stdin:
                what, *args = line.split()
                n = int(args[0])
                if what == "single":
                    out = {"us": await _per_request(app, one, n, clients)}
                else:
                    k = int(args[1])
                    rows = np.arange(k) % len(x)
                    table = json.dumps(
                        {"samples": x[rows].tolist(), "objects": [f"o{i}" for i in range(k)]}
                    ).encode()
                    batch = json.dumps({"samples": x[rows].tolist()}).encode()
                    singles = [json.dumps({"samples": [x[i].tolist()]}).encode() for i in rows]
                    reps = max(1, n // k)
                    start = time.process_time()
                    for _ in range(reps):
                        for body in singles:
                            await _call(app, body)
                    single_s = (time.process_time() - start) / reps
                    out = {
                        "table_us": await _per_request(app, table, reps),
                        "batch_us": await _per_request(app, batch, reps),
                        "singles_us": single_s * 1e6,
                    }
                print(json.dumps(out), flush=True)


# ----------------------------------------------------------------- parent side
def _start(tree: Path, method: str | None, clients: int) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(tree), "TACTILE_TORCH_THREADS": "1"}
    options = ["--clients", str(clients)] + (["--method", method] if method else [])
    proc = subprocess.Popen(
        [sys.executable, str(Path(__file__).resolve()), "--child", *options],
        cwd=tree,
        env=env,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    line = proc.stdout.readline()
    if not line or not json.loads(line).get("ready"):
        raise RuntimeError(f"the service of {tree} did not start")
    return proc


def _ask(proc: subprocess.Popen, command: str) -> dict:
    proc.stdin.write(command + "\n")
    proc.stdin.flush()
    return json.loads(proc.stdout.readline())


def _spread(values: list[float], digits: int = 3) -> dict:
    return {
        "median": round(statistics.median(values), digits),
        "range": [round(min(values), digits), round(max(values), digits)],
    }


def _git(tree: Path) -> str:
    """The tree's commit, stamped ``+changes`` where its files differ from it."""

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", "-C", str(tree), *args], capture_output=True, text=True
        ).stdout.strip()

    dirty = git("status", "--porcelain", "--untracked-files=no")
    return git("rev-parse", "--short", "HEAD") + ("+changes" if dirty else "")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--against", type=Path, help="another checkout to compare with")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--requests", type=int, default=2000)
    parser.add_argument("--objects", type=int, default=12)
    parser.add_argument(
        "--method", help="serve this method as the embedded default fits it (default: best, quick)"
    )
    parser.add_argument("--clients", type=int, default=1, help="requests sent at a time")
    parser.add_argument("--no-tables", action="store_true", help="single requests only")
    parser.add_argument("--json", type=Path, help="write the report here too")
    args = parser.parse_args()
    if args.child:
        asyncio.run(_child(args.method, args.clients))
        return 0
    if args.clients < 1:
        parser.error(f"--clients must be at least 1, got {args.clients}")
    this = _start(HERE, args.method, args.clients)
    other = _start(args.against.resolve(), args.method, args.clients) if args.against else None
    rounds: list[dict] = []
    try:
        for i in range(args.rounds):
            row: dict = {}
            # the two trees take turns going first: neither always follows the other
            for name, proc in (("this", this), ("other", other))[:: 1 if i % 2 == 0 else -1]:
                if proc is not None:
                    row[f"{name}_us"] = _ask(proc, f"single {args.requests}")["us"]
            if other is not None:
                row["ratio"] = row["this_us"] / row["other_us"]
            rounds.append(row)
            print(json.dumps({k: round(v, 3) for k, v in row.items()}), flush=True)
        for row in [] if args.no_tables else rounds:  # after every single-request round
            row.update(_ask(this, f"table {args.requests // 4} {args.objects}"))
            row["table_over_singles"] = row["table_us"] / row["singles_us"]
            row["table_over_batch"] = row["table_us"] / row["batch_us"]
    finally:
        for proc in (this, other):
            if proc is not None:
                proc.stdin.close()
                proc.wait(timeout=60)
    report = {
        "command": " ".join(["python -m bench.recognize_route", *sys.argv[1:]]),
        "this": _git(HERE),
        "against": _git(args.against) if args.against else None,
        "rounds": rounds,
        "single_us": _spread([r["this_us"] for r in rounds], 1),
        "method": args.method or "best (the tests' quick parameters)",
        "clients": args.clients,
    }
    if not args.no_tables:
        report["objects"] = args.objects
        report["table_over_singles"] = _spread([r["table_over_singles"] for r in rounds])
        report["table_over_batch"] = _spread([r["table_over_batch"] for r in rounds])
    if other is not None:
        report["single_us_against"] = _spread([r["other_us"] for r in rounds], 1)
        report["single_ratio"] = _spread([r["ratio"] for r in rounds])
    print(json.dumps({k: v for k, v in report.items() if k != "rounds"}, indent=1))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
