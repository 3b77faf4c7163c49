"""What a robot pays to take the model offline: the bundle's size, the download, and
recognition from the file with ``tactile-zsl recognize`` (a fresh process per call).

    .venv/bin/python -m bench.offline_model [--dataset simulated] [--method best] [--repeats 5]
    .venv/bin/python -m bench.offline_model --dataset phac2:../shared/data/phac2

A fresh SQLite store is bootstrapped on ``--dataset`` (the embedded default: the built-in
simulator) with ``--method``, in process (the API app under TestClient, as the tests do),
and given ``--novel`` registered classes, so the bundle carries a novel part. Printed, as
medians over ``--repeats``: ``GET /v1/models/{version}/bundle`` (the first download, which
joins the version's parts into one file, each later one, which an API process answers from
its copy, and a 304 revalidation), ``bundle.load`` of the file and one recognition in
process, and the wall time of a ``tactile-zsl recognize`` process for 1 and for 1,024
samples (start-up, imports, load and answer), and the round trip of one line through a
running ``recognize --lines``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from fastapi.testclient import TestClient

from app.api.main import create_app
from app.config import Settings
from app.framework import bundle
from app.framework.registry import DEFAULT_METHOD
from app.testing.harness import tactile_zsl
from bench.bench_framework import timed
from bench.withdrawal import print_report, timed_round, unused_attributes
from worker import Worker


def median_seconds(fn, repeats: int) -> float:
    return float(np.median(timed(fn, repeats)))


def lines_process_seconds(path: Path, sample: np.ndarray, n: int) -> float:
    """Median seconds from writing one line to a running ``recognize --lines`` process to
    reading its answer (after one warm-up line)."""
    proc = subprocess.Popen(
        [*tactile_zsl(), "recognize", "--model", str(path), "--lines", "-"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    line = json.dumps({"samples": [sample.tolist()]}) + "\n"

    def one() -> None:
        proc.stdin.write(line)
        proc.stdin.flush()
        assert json.loads(proc.stdout.readline())["results"]

    try:
        one()
        return median_seconds(one, n)
    finally:
        proc.stdin.close()
        proc.wait(timeout=60)


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--dataset", default="simulated")
    ap.add_argument("--method", default=DEFAULT_METHOD)
    ap.add_argument("--novel", type=int, default=3, help="classes to register before downloading")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        settings = Settings(
            data_dir=tmp / "store", embedded_worker=False, dataset=args.dataset, method=args.method
        )
        with TestClient(create_app(settings)) as client:
            worker = Worker(
                settings,
                client.app.state.service.sessions,
                on_activate=client.app.state.service.holder.serve,
            )
            for i in range(args.novel):
                r = client.post(
                    "/v1/classes",
                    json={"name": f"object-{i}", "attributes": unused_attributes(client, i)},
                )
                timed_round(worker, client, r.json()["job"]["id"])
            version = client.get("/v1/models/active").json()["version"]
            url = f"/v1/models/{version}/bundle"
            first_download = median_seconds(lambda: client.get(url), 1)  # joins the version's parts
            r = client.get(url)
            data, etag = r.content, r.headers["etag"]
            download = median_seconds(lambda: client.get(url), args.repeats)  # the process's copy
            revalidate = median_seconds(
                lambda: client.get(url, headers={"If-None-Match": etag}), args.repeats
            )
        path = tmp / "robot.bundle"
        path.write_bytes(data)
        model = bundle.load(path)
        rng = np.random.default_rng(0)
        batch = rng.normal(size=(1024, *model.input_shape)).astype(np.float32)
        np.save(tmp / "one.npy", batch[0])
        np.save(tmp / "batch.npy", batch)
        load = median_seconds(lambda: bundle.load(path), args.repeats)
        one = median_seconds(lambda: model.recognize_batch(batch[:1]), args.repeats)

        def run_cli(samples: str) -> None:
            out = subprocess.run(
                [*tactile_zsl(), "recognize", "--model", str(path), str(tmp / samples)],
                capture_output=True,
                text=True,
                check=True,
            )
            assert json.loads(out.stdout)["results"]

        first_process = median_seconds(lambda: run_cli("one.npy"), 1)  # may fill numba's cache
        cli_one = median_seconds(lambda: run_cli("one.npy"), args.repeats)
        cli_batch = median_seconds(lambda: run_cli("batch.npy"), args.repeats)
        per_line = lines_process_seconds(path, batch[0], 20 * args.repeats)
    print_report(
        {
            "dataset": args.dataset,
            "method": args.method,
            "model_version": version,
            "classes": len(model.registry.known_names) + len(model.registry.novel_names),
            "bundle_bytes": len(data),
            "median_seconds": {
                "first download of a version (GET .../bundle, joins its parts)": round(
                    first_download, 3
                ),
                "each later download of it": round(download, 4),
                "revalidate (304)": round(revalidate, 4),
                "bundle.load": round(load, 3),
                "recognize 1 sample in process": round(one, 4),
                "first tactile-zsl recognize process, 1 sample": round(first_process, 2),
                "tactile-zsl recognize process, 1 sample": round(cli_one, 2),
                "tactile-zsl recognize process, 1024 samples": round(cli_batch, 2),
                "tactile-zsl recognize --lines, 1 sample per line": round(per_line, 4),
            },
        }
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
