"""Framework speed: base training on PHAC-2, zero-shot and one-shot enrolment, batch inference.

    .venv/bin/python bench/bench_framework.py [--phac2 ../shared/data/phac2] [--method paper]

Prints one JSON object; docs/BENCHMARKS.md records its figures with the machine.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time

import numpy as np

from app.data.phac2 import load_phac2
from app.data.simulator import simulate_dataset
from app.framework.registry import make_method


def timed(fn, repeat: int) -> list[float]:
    out = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--phac2",
        default=os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data", "phac2"),
    )
    ap.add_argument("--method", default="paper")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    report: dict = {
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs",
        "method": args.method,
    }

    # Base training on all 60 PHAC-2 objects.
    ds = load_phac2(args.phac2)
    novel_idx = np.arange(54, 60)
    known = ds.select_classes(np.arange(54))
    novel = ds.select_classes(novel_idx)
    t = time.perf_counter()
    model = make_method(args.method).fit(known, progress=False)
    report["phac2_base_training_s"] = time.perf_counter() - t
    report["phac2_training_stages_s"] = model.metrics.get("timings")

    # Zero-shot enrolment of one class, then a one-shot update of it.
    names = [f"bench-{n}" for n in novel.class_names]
    zsl = timed(
        lambda: model.add_novel_classes(
            names[:1], novel.class_attributes[:1], allow_known_vectors=True
        ),
        args.repeat,
    )
    report["zero_shot_enrolment_s_median"] = statistics.median(zsl)
    enrolled = model.add_novel_classes(
        names[:1], novel.class_attributes[:1], allow_known_vectors=True
    )
    osl = timed(lambda: enrolled.add_one_shot(names[0], novel.samples[:1]), args.repeat)
    report["one_shot_update_s_median"] = statistics.median(osl)

    # Batch inference on the paper's 32 x 30 tactile images.
    sim = simulate_dataset(n_objects=30, trials_per_object=10, seed=0)
    sim_model = make_method(args.method).fit(sim.select_classes(np.arange(24)), progress=False)
    sim_model = sim_model.add_novel_classes(
        sim.class_names[24:], sim.class_attributes[24:], allow_known_vectors=True
    )
    batch = np.tile(sim.samples, (4, 1, 1))[:1024]
    sim_model.recognize(batch)
    runs = timed(lambda: sim_model.recognize(batch), args.repeat)
    report["batch_inference_32x30_samples_per_s"] = len(batch) / statistics.median(runs)
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
