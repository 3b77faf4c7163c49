"""What robots waiting for their enrolments cost the API: polling against long polling.

    .venv/bin/python -m bench.job_wait --robots 100 --seconds 20 [--postgres URL]

One API process and no worker, so every robot's job stays queued and each robot waits the
whole phase: the worst case, a retrain that takes long. Phase ``poll``: each robot asks
``GET /v1/jobs/{id}`` every ``--interval`` seconds (the advice before long polling);
phase ``wait``: each robot asks ``GET /v1/jobs/{id}?wait=20`` again whenever one answers.
Reported per phase: requests answered and the API process's CPU time, as a share of one
core. Only 127.0.0.1 is ever targeted.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import sys
import tempfile
import time
from pathlib import Path

import httpx

from app.testing.harness import Cluster
from app.testing.service import fresh_postgres_database, quick_dataset, unused_vectors
from bench.load import process_cpu_s


async def robot(
    client: httpx.AsyncClient, job_id: int, until: float, wait: float, interval: float
) -> int:
    answered = 0
    while time.monotonic() < until:
        params = {"wait": wait} if wait else {}
        r = await client.get(f"/v1/jobs/{job_id}", params=params)
        assert r.status_code == 200 and r.json()["status"] == "queued", r.text
        answered += 1
        if not wait:
            await asyncio.sleep(interval)
    return answered


async def phase(
    url: str, pid: int, job_ids: list[int], seconds: float, wait: float, interval: float
) -> dict:
    limits = httpx.Limits(
        max_connections=len(job_ids) + 8, max_keepalive_connections=len(job_ids) + 8
    )
    async with httpx.AsyncClient(base_url=url, timeout=wait + 30, limits=limits) as client:
        cpu = process_cpu_s(pid)
        start = time.monotonic()
        counts = await asyncio.gather(
            *(robot(client, j, start + seconds, wait, interval) for j in job_ids)
        )
        elapsed = time.monotonic() - start
        used = process_cpu_s(pid) - cpu
    return {
        "requests": sum(counts),
        "seconds": round(elapsed, 1),
        "api_cpu_pct_of_one_core": round(100 * used / elapsed, 1),
        "api_cpu_ms_per_robot_minute": round(1000 * used / len(job_ids) / (elapsed / 60), 1),
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--robots", type=int, default=100)
    p.add_argument("--seconds", type=float, default=20)
    p.add_argument("--interval", type=float, default=0.5, help="poll phase: seconds between polls")
    p.add_argument("--postgres", default="")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as stack:
        url = stack.enter_context(fresh_postgres_database(args.postgres)) if args.postgres else ""
        cluster = Cluster(Path(tmp) / "data", url, n_api=1, n_workers=0)
        try:
            cluster.start()
            cluster.wait_ready()
            api = cluster.urls[0]
            pid = next(proc.popen.pid for proc in cluster.procs if proc.port)
            job_ids = []
            with httpx.Client(base_url=api, timeout=30) as c:
                for i, vector in enumerate(unused_vectors(quick_dataset(), args.robots)):
                    r = c.post(
                        "/v1/classes", json={"name": f"robot-{i}", "attribute_vector": vector}
                    )
                    assert r.status_code == 202, r.text
                    job_ids.append(r.json()["job"]["id"])
            report = {"robots": args.robots, "store": "postgresql" if url else "sqlite"}
            report["poll"] = asyncio.run(phase(api, pid, job_ids, args.seconds, 0, args.interval))
            report["wait"] = asyncio.run(phase(api, pid, job_ids, args.seconds, 20, 0))
        finally:
            cluster.stop()
    report["interval_s"] = args.interval
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
