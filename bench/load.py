"""Load on 2 API processes (plus 1 worker) on loopback, SQLite and PostgreSQL side by side.

    .venv/bin/python -m bench.load --seconds 15 --clients 32 [--postgres URL]
    .venv/bin/python -m bench.load --seconds 15 --clients 32 --embedded   # plain `serve`

The service runs as deployed by default (the embedded simulated dataset, the default method,
no rate limit). A lean asyncio HTTP/1.1 client measures requests/s and p50/p99 latency of
single-sample JSON recognition and of binary (.npy) batch recognition, then the
enrollment-to-live times (POST /v1/classes, then POST /v1/classes/{id}/samples, until the
job succeeded with it in the active model, and until *every* API process answers
recognitions with that model version), idle and while the single-sample load runs. Each load
phase also reports ``cpu_steal_pct``, the share of CPU time the hypervisor gave to other
guests meanwhile (on a shared VM, a phase with high steal measured the neighbours, not the
service), and ``cpu_us_per_request``, the CPU time each process (every API, the worker, this
load generator) spent per answered request: where a 2-core budget goes. After the phases,
``resident_mb`` gives each process's resident memory (a multi-process `serve` lists its own,
then each API process's). ``--phases single,batch`` skips the enrollment phases; ``--phases
enroll,reads`` also measures the read endpoints that clients poll (jobs, active model,
readiness).
Only 127.0.0.1 is ever targeted.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import functools
import io
import json
import multiprocessing
import os
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import numpy as np
import uvloop

from app.config import Settings
from app.data.sources import load_dataset
from app.framework.registry import DEFAULT_METHOD
from app.testing.harness import Cluster
from app.testing.service import fresh_postgres_database, unused_vectors


def cpu_jiffies() -> list[int] | None:
    """The machine's CPU time counters (/proc/stat: user … steal), or None off Linux."""
    try:
        with open("/proc/stat") as f:
            return [int(v) for v in f.readline().split()[1:9]]
    except OSError:
        return None


def steal_pct(before: list[int] | None, after: list[int] | None) -> float | None:
    """Share of CPU time the hypervisor gave to other guests ("steal") between two readings:
    on a shared VM the figures of a phase with high steal are not the machine's capacity."""
    if before is None or after is None:
        return None
    delta = [b - a for a, b in zip(before, after, strict=True)]
    return round(100 * delta[7] / sum(delta), 1) if sum(delta) else 0.0


def child_pids(pid: int) -> list[int]:
    """The processes ``pid`` started (OSError off Linux or once it is gone)."""
    kids = []
    for tid in os.listdir(f"/proc/{pid}/task"):
        with open(f"/proc/{pid}/task/{tid}/children") as f:
            kids += [int(c) for c in f.read().split()]
    return kids


def process_cpu_s(pid: int, children: bool = True) -> float | None:
    """CPU seconds (user + system) a process has used so far, with its children's (the API
    processes of a multi-process `serve`) unless ``children`` is False; None off Linux."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rpartition(")")[2].split()
        kids = child_pids(pid) if children else []
    except OSError:
        return None
    own = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return own + sum(process_cpu_s(k) or 0.0 for k in kids)


def resident_mb(pid: int) -> list[float] | None:
    """Resident memory (VmRSS, MB) of a process, then of each of its children (the API
    processes of a multi-process `serve`); None off Linux."""
    try:
        with open(f"/proc/{pid}/status") as f:
            rss = next(int(line.split()[1]) for line in f if line.startswith("VmRSS:"))
        kids = child_pids(pid)
    except (OSError, StopIteration):
        return None
    return [round(rss / 1024, 1)] + [m for k in kids for m in resident_mb(k) or []]


def cpu_per_request(pids: dict[str, int], before: dict, after: dict, requests: int) -> dict:
    """Microseconds of CPU each process spent per answered request during a phase."""
    out = {}
    for name in pids:
        if before.get(name) is not None and after.get(name) is not None and requests:
            out[name] = round(1e6 * (after[name] - before[name]) / requests)
    return out


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) * 1000 if values else float("nan")


class Connection:
    """One keep-alive HTTP/1.1 connection that sends a prepared request and reads the
    answer. Hand-rolled on asyncio streams because a full client (httpx) costs more CPU
    per request than the service does, and here it shares the same 2 cores."""

    def __init__(self, url: str) -> None:
        parts = urlsplit(url)
        self.host, self.port = parts.hostname, parts.port
        self.reader: asyncio.StreamReader | None = None
        self.writer: asyncio.StreamWriter | None = None

    @staticmethod
    def prepare(method: str, path: str, body: bytes, content_type: str) -> bytes:
        head = (
            f"{method} {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: {content_type}\r\n"
            f"Content-Length: {len(body)}\r\n\r\n"
        )
        return head.encode() + body

    async def send(self, request: bytes) -> int:
        """The response status; the body is read and dropped."""
        return (await self.fetch(request))[0]

    async def fetch(self, request: bytes) -> tuple[int, bytes]:
        """The response status and body."""
        if self.writer is None:
            self.reader, self.writer = await asyncio.open_connection(self.host, self.port)
        self.writer.write(request)
        head = await self.reader.readuntil(b"\r\n\r\n")
        length = 0
        for line in head.split(b"\r\n")[1:]:
            name, _, value = line.partition(b":")
            if name.strip().lower() == b"content-length":
                length = int(value)
        body = await self.reader.readexactly(length)
        return int(head[9:12]), body

    async def get_json(self, path: str) -> dict:
        return await self.fetch_json(self.prepare("GET", path, b"", "application/json"))

    async def fetch_json(self, request: bytes) -> dict:
        status, body = await self.fetch(request)
        if status != 200:
            raise RuntimeError(f"{request.split(b' HTTP/')[0]!r}: {status} {body[:200]!r}")
        return json.loads(body)

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.writer = None


async def hammer(
    urls,
    seconds,
    clients,
    request: bytes,
    stop: asyncio.Event | None = None,
    pids: dict[str, int] | None = None,
) -> dict:
    """``clients`` connections, each sending ``request`` back to back for ``seconds`` (or
    until ``stop`` is set). With ``pids`` (name → process id), also the CPU time each of
    those processes and this load generator spent per answered request."""
    latencies, errors = [], 0
    deadline = time.monotonic() + seconds
    stop = stop or asyncio.Event()

    async def one(i: int) -> None:
        nonlocal errors
        conn = Connection(urls[i % len(urls)])
        try:
            while time.monotonic() < deadline and not stop.is_set():
                t = time.perf_counter()
                try:
                    ok = await conn.send(request) == 200
                except (OSError, asyncio.IncompleteReadError, ValueError):
                    conn.close()
                    ok = False
                if ok:
                    latencies.append(time.perf_counter() - t)
                else:
                    errors += 1
        finally:
            conn.close()

    pids = {**(pids or {}), "load_generator": os.getpid()}

    def cpu() -> dict:  # the load generator's children are the service's processes
        return {
            name: process_cpu_s(pid, children=name != "load_generator")
            for name, pid in pids.items()
        }

    start, jiffies = time.monotonic(), cpu_jiffies()
    cpu_before = cpu()
    await asyncio.gather(*(one(i) for i in range(clients)))
    elapsed = time.monotonic() - start
    cpu_after = cpu()
    return {
        "requests": len(latencies),
        "errors": errors,
        "rps": round(len(latencies) / elapsed, 1),
        "p50_ms": round(pct(latencies, 50), 2),
        "p99_ms": round(pct(latencies, 99), 2),
        "cpu_steal_pct": steal_pct(jiffies, cpu_jiffies()),
        "cpu_us_per_request": cpu_per_request(pids, cpu_before, cpu_after, len(latencies)),
    }


async def enrollment_to_live(
    urls, dataset, n: int, offset: int, poll: float
) -> dict[str, list[float]]:
    """Seconds from ``POST /v1/classes``, then from ``POST …/samples`` (one real sample of
    the new class), until its job succeeded with it in the active model ("active"), and
    until every API process answers recognitions with that model version ("served")."""
    vectors = unused_vectors(dataset, offset + n)[offset:]
    times: dict[str, list[float]] = {
        f"{kind}_{to}": [] for kind in ("class", "sample") for to in ("active", "served")
    }
    # polls on lean keep-alive connections: it shares the 2 cores with the service
    polls = {url: Connection(url) for url in urls}
    which = Connection.prepare(
        "POST",
        "/v1/recognize",
        json.dumps({"samples": dataset.samples[:1].tolist()}).encode(),
        "application/json",
    )
    async with httpx.AsyncClient(timeout=30) as c:

        async def live(kind: str, job: dict, start: float) -> None:
            while job["status"] != "succeeded":
                if job["status"] == "failed":
                    raise RuntimeError(f"enrollment job failed: {job['error']}")
                await asyncio.sleep(poll)
                job = await polls[urls[0]].get_json(f"/v1/jobs/{job['id']}")
            times[f"{kind}_active"].append(time.perf_counter() - start)
            pending = list(urls)
            while pending:
                for url in list(pending):
                    if (await polls[url].fetch_json(which))["model_version"] >= job[
                        "model_version"
                    ]:
                        pending.remove(url)
                if pending:
                    await asyncio.sleep(poll)
            times[f"{kind}_served"].append(time.perf_counter() - start)

        for i, v in enumerate(vectors):
            t = time.perf_counter()
            r = await c.post(
                f"{urls[0]}/v1/classes", json={"name": f"load-{offset + i}", "attribute_vector": v}
            )
            await live("class", r.json()["job"], t)
            t = time.perf_counter()
            r = await c.post(
                f"{urls[0]}/v1/classes/{r.json()['class']['id']}/samples",
                json={"sample": dataset.samples[i].tolist()},
            )
            await live("sample", r.json()["job"], t)
    for conn in polls.values():
        conn.close()
    return times


def enroll_in_child(urls, dataset_name: str, n: int, offset: int, poll: float) -> dict:
    """``enrollment_to_live`` in a process of its own. Beside the load in this process, its
    HTTP client (httpx: a few milliseconds of CPU per call) stalled the load generator's
    event loop, and every request in flight then measured that stall as service latency."""
    return asyncio.run(enrollment_to_live(urls, child_dataset(dataset_name), n, offset, poll))


@functools.cache
def child_dataset(name: str):
    """The dataset, simulated once per child process: simulating it took CPU from the
    service in the middle of the measured load."""
    return load_dataset(name)


READ_PATHS = ("/readyz", "/v1/attributes", "/v1/classes/1", "/v1/models/active", "/v1/jobs/1")


async def reads(urls, seconds: float, pids: dict[str, int], clients: int = 8) -> dict:
    """The read endpoints robots and dashboards poll, one after another, each from
    ``clients`` connections: their requests/s, latency and CPU per request."""
    out = {}
    for path in READ_PATHS:
        request = Connection.prepare("GET", path, b"", "application/json")
        if (await Connection(urls[0]).fetch(request))[0] != 200:
            continue  # /v1/jobs/1 exists once an enrolment ran
        out[path] = await hammer(urls, seconds, clients, request, pids=pids)
    return out


async def run(
    cluster: Cluster,
    seconds: float,
    clients: int,
    batch: int,
    dataset,
    dataset_name: str,
    phases: set[str],
    poll: float,
) -> dict:
    urls = cluster.urls
    pids = {p.name: p.popen.pid for p in cluster.procs if p.popen is not None}
    samples = dataset.samples
    single = Connection.prepare(
        "POST",
        "/v1/recognize",
        json.dumps({"samples": samples[:1].tolist()}).encode(),
        "application/json",
    )
    buf = io.BytesIO()
    np.save(buf, np.resize(samples, (batch, *samples.shape[1:])).astype(np.float32))
    npy = Connection.prepare("POST", "/v1/recognize", buf.getvalue(), "application/x-npy")
    await hammer(urls, 2, clients, single)  # warm-up
    out = {}
    if "single" in phases:
        out["single"] = await hammer(urls, seconds, clients, single, pids=pids)
    if "batch" in phases:
        b = await hammer(urls, seconds, 4, npy, pids=pids)
        b["samples_per_s"] = round(b["rps"] * batch, 1)
        out[f"npy_batch_{batch}"] = b
    if "enroll" in phases:
        out.update(await enrollment_phases(urls, clients, single, dataset_name, poll, pids))
    if "reads" in phases:  # last: after an enrolment there is a job to poll
        out["reads"] = await reads(urls, seconds, pids)
    out["resident_mb"] = {name: resident_mb(pid) for name, pid in pids.items()}  # after the load
    return out


async def enrollment_phases(
    urls, clients: int, single: bytes, dataset_name: str, poll: float, pids: dict[str, int]
) -> dict:
    """Enrollment to live, idle and under the single-sample load, and that load's figures."""
    out = {}
    loop = asyncio.get_running_loop()
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as child:
        idle = await loop.run_in_executor(child, enroll_in_child, urls, dataset_name, 3, 0, poll)
        done = asyncio.Event()
        load_task = asyncio.create_task(hammer(urls, 600, clients, single, done, pids=pids))
        await asyncio.sleep(1)
        busy = await loop.run_in_executor(child, enroll_in_child, urls, dataset_name, 3, 3, poll)
        done.set()
        # before the pool shuts down: joining the child blocks this event loop (~0.2 s),
        # and the requests then in flight measured that as service latency
        out["single_during_enrollments"] = await load_task
    for key in idle:  # class_to_active_s, class_to_served_s, sample_to_...
        out[key.replace("_", "_to_", 1) + "_s"] = {
            "idle_median": round(statistics.median(idle[key]), 2),
            "under_load_median": round(statistics.median(busy[key]), 2),
            "under_load_max": round(max(busy[key]), 2),
        }
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--postgres", default="")
    p.add_argument("--seconds", type=float, default=15)
    p.add_argument("--clients", type=int, default=32)
    p.add_argument("--batch", type=int, default=1024)
    p.add_argument(
        "--embedded",
        action="store_true",
        help="one plain `tactile-zsl serve` (its default number of processes, each with "
        "a worker thread) instead of 2 single-process APIs + 1 worker",
    )
    p.add_argument(
        "--env",
        action="append",
        default=[],
        metavar="TACTILE_X=V",
        help="extra service setting for every process (repeatable)",
    )
    p.add_argument(
        "--dataset",
        default="simulated",
        help="bootstrap data, as TACTILE_DATASET (default: the embedded default)",
    )
    p.add_argument(
        "--method",
        default=DEFAULT_METHOD,
        help=f"recognition method, as TACTILE_METHOD (default: {DEFAULT_METHOD})",
    )
    p.add_argument(
        "--poll-seconds",
        type=float,
        default=0.02,
        help="how often the enrolling client polls its job and the APIs' active model",
    )
    p.add_argument(
        "--phases",
        default="single,batch,enroll",
        help="which phases to run, comma-separated (default: the three of the goals; "
        "'reads' adds the polled read endpoints, 8 clients each)",
    )
    args = p.parse_args()
    phases = set(args.phases.split(","))
    known = {"single", "batch", "enroll", "reads"}
    if not phases <= known:
        p.error(f"--phases: unknown phase(s) {sorted(phases - known)}")
    dataset = load_dataset(args.dataset)
    # the deployed model, not the tests' quick one; no rate limit: this measures capacity
    env = {
        "TACTILE_DATASET": args.dataset,
        "TACTILE_METHOD": args.method,
        "TACTILE_METHOD_PARAMS": "{}",
        "TACTILE_RATE_LIMIT": "0",
        **dict(a.split("=", 1) for a in args.env),
    }
    with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as stack:
        url = stack.enter_context(fresh_postgres_database(args.postgres)) if args.postgres else ""
        # --embedded: plain `serve`, with as many processes as it starts on this machine
        shape = (
            {
                "n_api": 1,
                "n_workers": 0,
                "embedded_worker": True,
                "processes": Settings().api_processes,
            }
            if args.embedded
            else {"n_api": 2, "n_workers": 1}
        )
        cluster = Cluster(Path(tmp) / "data", url, extra_env=env, **shape)
        try:
            cluster.start()
            cluster.wait_ready()
            report = uvloop.run(
                run(
                    cluster,
                    args.seconds,
                    args.clients,
                    args.batch,
                    dataset,
                    args.dataset,
                    phases,
                    args.poll_seconds,
                )
            )
        finally:
            cluster.stop()
    report.update(
        store="postgresql" if args.postgres else "sqlite",
        clients=args.clients,
        processes=f"plain serve: {shape['processes']} API process(es) on one port, worker "
        "thread in each"
        if args.embedded
        else "2 APIs + 1 worker",
        dataset=args.dataset,
        method=args.method,
    )
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
