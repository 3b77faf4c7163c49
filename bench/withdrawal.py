"""How long a withdrawal, or a class's new description, takes to reach the served model,
against an enrolment.

    .venv/bin/python bench/withdrawal.py [--dataset simulated] [--method best] [--repeats 3]
    .venv/bin/python bench/withdrawal.py --dataset phac2:../shared/data/phac2

A fresh SQLite store is bootstrapped on ``--dataset`` (the embedded default: the built-in
simulator) with ``--method``, in process (the API app under TestClient and a worker run by
hand, as the tests do). Per repeat: a class is registered and given two samples, then one
sample is withdrawn, the class described anew (``PATCH``), and withdrawn; and a second
class is given ``PROMOTION`` samples, which promotes it to a known class, and loses one of
them again, which makes it novel again. Printed: the worker's round (claim to active) for
each step. Enrolments are incremental updates; a withdrawal or a new description in the
novel part rebuilds the novel classes on the base's known part where the method allows it
(``novel_part_separable``: ``best``), else it is a full retrain, as a promotion and a
withdrawal from the known part always are.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from fastapi.testclient import TestClient

from app.api.main import create_app
from app.config import Settings
from app.framework.registry import DEFAULT_METHOD
from worker import Worker

PROMOTION = 3  # real samples that make a novel class known


def cpu_model() -> str:
    for line in (
        Path("/proc/cpuinfo").read_text().splitlines() if Path("/proc/cpuinfo").exists() else []
    ):
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return platform.machine()


def print_report(report: dict) -> None:
    """``report`` as indented JSON on stdout, with the machine it was measured on last."""
    machine = f"{cpu_model()}, {os.cpu_count()} CPUs, Python {platform.python_version()}"
    print(json.dumps({**report, "machine": machine}, indent=2))


def timed_round(worker: Worker, client: TestClient, job_id: int) -> float:
    start = time.perf_counter()
    assert worker.run_once() >= 1
    seconds = time.perf_counter() - start
    job = client.get(f"/v1/jobs/{job_id}").json()
    assert job["status"] == "succeeded", job
    return seconds


def unused_attributes(client: TestClient, i: int) -> list[str]:
    """The first two attributes (after ``i`` shifts) no class has as its whole vector."""
    names = client.get("/v1/attributes").json()["attributes"]
    taken = {
        tuple(c["attributes"])
        for c in client.get("/v1/classes", params={"limit": 1000}).json()["classes"]
    }
    pairs = [(a, b) for k, a in enumerate(names) for b in names[k + 1 :] if (a, b) not in taken]
    return list(pairs[i])


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--dataset", default="simulated")
    ap.add_argument("--method", default=DEFAULT_METHOD)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        settings = Settings(
            data_dir=Path(tmp),
            embedded_worker=False,
            dataset=args.dataset,
            method=args.method,
            promotion_threshold=PROMOTION,
        )
        started = time.perf_counter()
        app = create_app(settings)
        times: dict[str, list[float]] = {
            k: []
            for k in (
                "register",
                "add sample",
                "withdraw sample",
                "describe anew",
                "withdraw class",
                "promotion (full retrain)",
                "withdraw a promoted class's sample (full retrain)",
            )
        }
        with TestClient(app) as client:
            print(f"bootstrapped in {time.perf_counter() - started:.1f} s", file=sys.stderr)
            worker = Worker(
                settings, app.state.service.sessions, on_activate=app.state.service.holder.serve
            )
            worker.warm_up()
            shape = app.state.service.holder.current.recognizer.input_shape
            rng = np.random.default_rng(0)
            for i in range(args.repeats):
                r = client.post(
                    "/v1/classes",
                    json={"name": f"object-{i}", "attributes": unused_attributes(client, i)},
                )
                cid = r.json()["class"]["id"]
                times["register"].append(timed_round(worker, client, r.json()["job"]["id"]))
                sample_ids = []
                for _ in range(2):
                    sample = rng.normal(size=shape).astype(np.float32).tolist()
                    r = client.post(f"/v1/classes/{cid}/samples", json={"sample": sample})
                    sample_ids.append(r.json()["sample_id"])
                    times["add sample"].append(timed_round(worker, client, r.json()["job"]["id"]))
                r = client.delete(f"/v1/classes/{cid}/samples/{sample_ids[0]}")
                times["withdraw sample"].append(timed_round(worker, client, r.json()["job"]["id"]))
                r = client.patch(
                    f"/v1/classes/{cid}", json={"attributes": unused_attributes(client, i + 1)}
                )
                times["describe anew"].append(timed_round(worker, client, r.json()["job"]["id"]))
                r = client.delete(f"/v1/classes/{cid}")
                times["withdraw class"].append(timed_round(worker, client, r.json()["job"]["id"]))

                r = client.post(
                    "/v1/classes",
                    json={"name": f"promoted-{i}", "attributes": unused_attributes(client, i)},
                )
                cid = r.json()["class"]["id"]
                timed_round(worker, client, r.json()["job"]["id"])
                for k in range(PROMOTION):
                    sample = rng.normal(size=shape).astype(np.float32).tolist()
                    r = client.post(f"/v1/classes/{cid}/samples", json={"sample": sample})
                    if k < PROMOTION - 1:
                        timed_round(worker, client, r.json()["job"]["id"])
                times["promotion (full retrain)"].append(
                    timed_round(worker, client, r.json()["job"]["id"])
                )
                assert client.get(f"/v1/classes/{cid}").json()["kind"] == "known"
                r = client.delete(f"/v1/classes/{cid}/samples/{r.json()['sample_id']}")
                times["withdraw a promoted class's sample (full retrain)"].append(
                    timed_round(worker, client, r.json()["job"]["id"])
                )
                assert client.get(f"/v1/classes/{cid}").json()["kind"] == "novel"
                print(json.dumps({k: round(v[-1], 2) for k, v in times.items()}), file=sys.stderr)
    print_report(
        {
            "dataset": args.dataset,
            "method": args.method,
            "repeats": args.repeats,
            "median_seconds_to_active": {
                k: round(float(np.median(v)), 2) for k, v in times.items()
            },
        }
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
