"""What one enrolment costs in model bundles: writing the new version, and an API process
loading it (CPU time, median of repeats, in-process).

    .venv/bin/python -m bench.model_swap [--method best] [--dataset simulated] [--repeats 20]

The deployed default model (the embedded simulated dataset, `best`) is stored in a fresh
SQLite store, then the same model with one more novel class, the change an enrolment
makes. Printed: the whole bundle (``bundle.to_bytes``, as every version was stored before
split bundles) against the split one (a head plus shared parts): its size, writing it
(``bundle.split`` from scratch, and the worker's ``PartEncoder`` after the previous
version), and loading it (whole, against the head with the previous version's parts
cached, as an API process does), each load followed by the one-sample warm-up.
Last, the worker's pruning at the default retention (``TACTILE_KEEP_VERSIONS`` 100, so
it runs when 11 versions are over): one prune of 11 versions from a store of 111 (each
an enrolment's head), with the worker's memory of the heads it read at the previous
prune: each prune reads the 11 heads stored since, to find the parts still used; and,
for comparison, the same prune reading all 100 kept heads.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time

import numpy as np

from app.data.sources import load_dataset
from app.framework import bundle
from app.framework.registry import DEFAULT_METHOD, make_method
from app.service.bootstrap import model_classes
from app.store import bundles, repo, retention
from app.store.db import make_engine, make_sessionmaker
from app.store.models import Base
from app.testing.service import unused_vectors


def cpu_ms(fn, repeats: int) -> float:
    """Median CPU milliseconds of ``fn()``."""
    times = []
    for _ in range(repeats):
        start = time.process_time()
        fn()
        times.append(time.process_time() - start)
    return round(1000 * float(np.median(times[1:])), 1)


def prune_ms(sessions, base, dataset, repeats: int, remember: bool, keep: int = 100) -> float:
    """Median CPU milliseconds of one prune at the worker's slack (``keep // 10``). With
    ``remember``, as the worker prunes: the first prune, which reads every kept head, is
    not counted; without, every prune reads every kept head."""
    vector = np.asarray(unused_vectors(dataset, 1), np.float32)
    encoder = bundle.PartEncoder()
    times, n, refs = [], 0, {}
    for _ in range(repeats + 1):
        with sessions.begin() as s:
            while len(retention.prunable(s, keep)) <= keep // 10:
                n += 1
                model = base.add_novel_classes([f"enrolled-{n}"], vector)
                row = repo.add_version(
                    s,
                    method=model.method,
                    reason="update",
                    base_version=None,
                    bundle_sha256=bundles.store_model(s, encoder.split(model)),
                    input_shape=list(model.input_shape),
                    metrics={},
                    classes=model_classes(model),
                )
                repo.activate(s, row.version)
        start = time.process_time()
        with sessions.begin() as s:
            pruned = retention.prune(
                s, keep, slack=keep // 10, part_refs=refs if remember else None
            )
            assert len(pruned.versions) == keep // 10 + 1
        times.append(time.process_time() - start)
    return round(1000 * float(np.median(times[1:])), 1)


def main() -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--method", default=DEFAULT_METHOD)
    p.add_argument("--dataset", default="simulated")
    p.add_argument("--repeats", type=int, default=20)
    args = p.parse_args()
    dataset = load_dataset(args.dataset)
    base = make_method(args.method).fit(dataset)
    enrolled = base.add_novel_classes(
        ["enrolled"], np.asarray(unused_vectors(dataset, 1), np.float32)
    )

    with tempfile.TemporaryDirectory() as tmp:
        engine = make_engine(f"sqlite:///{tmp}/store.db")
        Base.metadata.create_all(engine)
        sessions = make_sessionmaker(engine)
        encoder = bundle.PartEncoder()
        with sessions.begin() as s:
            bundles.store_model(s, encoder.split(base))
            head = bundles.store_model(s, encoder.split(enrolled))
            whole = repo.store_bundle(s, bundle.to_bytes(enrolled))
        x = np.zeros((1, *base.input_shape), np.float32)

        def load(sha: str, cache: bundles.PartCache | None) -> None:
            with sessions() as s:
                bundles.load_model(s, sha, cache).recognize(x)

        cached: list[float] = []  # the served version's parts are held; the next one loads
        for _ in range(args.repeats):
            cache = bundles.PartCache()
            load(head, cache)
            start = time.process_time()
            load(head, cache)
            cached.append(time.process_time() - start)
        split_head, parts = bundle.split(enrolled)
        encoder.split(base)  # the worker's encoder holds the previous version's parts
        report = {
            "method": args.method,
            "dataset": args.dataset,
            "whole_bundle_bytes": len(bundle.to_bytes(enrolled)),
            "split_head_bytes": len(split_head),
            "split_parts": len(parts),
            "write_whole_ms": cpu_ms(lambda: bundle.to_bytes(enrolled), args.repeats),
            "write_split_from_scratch_ms": cpu_ms(lambda: bundle.split(enrolled), args.repeats),
            # each split follows the other version's, as the worker's do
            "write_split_after_previous_version_ms": round(
                cpu_ms(lambda: (encoder.split(enrolled), encoder.split(base)), args.repeats) / 2, 1
            ),
            "load_whole_ms": cpu_ms(lambda: load(whole, None), args.repeats),
            "load_split_parts_cached_ms": round(1000 * float(np.median(cached)), 1),
            "prune_11_of_111_versions_ms": prune_ms(
                sessions, base, dataset, min(args.repeats, 5), True
            ),
            "prune_reading_every_head_ms": prune_ms(
                sessions, base, dataset, min(args.repeats, 5), False
            ),
        }
        engine.dispose()
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
