"""Load on 2 API processes (plus 1 worker) on loopback, SQLite and PostgreSQL side by side.

    .venv/bin/python bench/load.py --seconds 15 --clients 32 [--postgres URL]

An async httpx client measures requests/s and p50/p99 latency of single-sample JSON
recognition and of binary (.npy) batch recognition, then the enrollment-to-live time
(POST /v1/classes until the class is in the active model of *both* API processes) while
the single-sample load keeps running. Only 127.0.0.1 is ever targeted.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import io
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.reliability.harness import Cluster  # noqa: E402
from tests.service_fixtures import fresh_postgres_database, quick_dataset, unused_vectors  # noqa: E402


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) * 1000 if values else float("nan")


async def hammer(urls, seconds, clients, make_request) -> dict:
    latencies, errors = [], 0
    deadline = time.monotonic() + seconds
    limits = httpx.Limits(max_connections=clients, max_keepalive_connections=clients)

    async def one(i: int, client: httpx.AsyncClient) -> None:
        nonlocal errors
        url = urls[i % len(urls)]
        while time.monotonic() < deadline:
            t = time.perf_counter()
            try:
                r = await make_request(client, url)
                ok = r.status_code == 200
            except httpx.HTTPError:
                ok = False
            if ok:
                latencies.append(time.perf_counter() - t)
            else:
                errors += 1

    async with httpx.AsyncClient(timeout=30, limits=limits) as client:
        start = time.monotonic()
        await asyncio.gather(*(one(i, client) for i in range(clients)))
        elapsed = time.monotonic() - start
    return {"requests": len(latencies), "errors": errors, "rps": round(len(latencies) / elapsed, 1),
            "p50_ms": round(pct(latencies, 50), 2), "p99_ms": round(pct(latencies, 99), 2)}


async def enrollment_to_live(urls, n: int, offset: int) -> list[float]:
    vectors = unused_vectors(quick_dataset(), offset + n)[offset:]
    times = []
    async with httpx.AsyncClient(timeout=30) as c:
        for i, v in enumerate(vectors):
            t = time.perf_counter()
            r = await c.post(f"{urls[0]}/v1/classes",
                             json={"name": f"load-{offset + i}", "attribute_vector": v})
            cid = r.json()["class"]["id"]
            pending = list(urls)
            while pending:
                for url in list(pending):
                    if (await c.get(f"{url}/v1/classes/{cid}")).json()["in_active_model"]:
                        pending.remove(url)
                await asyncio.sleep(0.02)
            times.append(time.perf_counter() - t)
    return times


async def run(cluster: Cluster, seconds: float, clients: int, batch: int) -> dict:
    urls = cluster.urls
    samples = quick_dataset().samples
    single = json.dumps({"samples": samples[:1].tolist()})
    buf = io.BytesIO()
    np.save(buf, np.resize(samples, (batch, *samples.shape[1:])).astype(np.float32))
    npy = buf.getvalue()
    jh = {"Content-Type": "application/json"}
    nh = {"Content-Type": "application/x-npy"}

    async def rec_single(c, url):
        return await c.post(f"{url}/v1/recognize", content=single, headers=jh)

    async def rec_batch(c, url):
        return await c.post(f"{url}/v1/recognize", content=npy, headers=nh)

    await hammer(urls, 2, clients, rec_single)  # warm-up
    out = {"single": await hammer(urls, seconds, clients, rec_single)}
    b = await hammer(urls, seconds, 4, rec_batch)
    b["samples_per_s"] = round(b["rps"] * batch, 1)
    out[f"npy_batch_{batch}"] = b
    idle = await enrollment_to_live(urls, 3, 0)
    load_task = asyncio.create_task(hammer(urls, seconds, clients, rec_single))
    await asyncio.sleep(1)
    busy = await enrollment_to_live(urls, 3, 3)
    out["single_during_enrollments"] = await load_task
    out["enroll_to_live_s"] = {"idle_median": round(statistics.median(idle), 2),
                               "under_load_median": round(statistics.median(busy), 2),
                               "under_load_max": round(max(busy), 2)}
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--postgres", default="")
    p.add_argument("--seconds", type=float, default=15)
    p.add_argument("--clients", type=int, default=32)
    p.add_argument("--batch", type=int, default=1024)
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as stack:
        url = stack.enter_context(fresh_postgres_database(args.postgres)) if args.postgres else ""
        cluster = Cluster(Path(tmp) / "data", url, n_api=2, n_workers=1)
        try:
            cluster.start()
            cluster.wait_ready()
            report = asyncio.run(run(cluster, args.seconds, args.clients, args.batch))
        finally:
            cluster.stop()
    report.update(store="postgresql" if args.postgres else "sqlite", clients=args.clients)
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
