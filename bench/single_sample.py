"""One sample in process: what ``best``'s ``recognize_batch`` costs for 1 sample against
its batch-amortised cost per sample, and where the 1-sample call spends its time.

    .venv/bin/python -m bench.single_sample [--repeats 3000] [--batch 1024] [--novel 6]
                                            [--clock wall|cpu]

``best`` is fitted on the embedded default (``simulate_dataset()``, seed 0), then, for a
second model, given ``--novel`` zero-shot classes (attribute vectors no known class has)
of which half get one one-shot sample each. For each model it prints first the ratio
(median seconds of a 1-sample call) / (median seconds of a ``--batch`` call / ``--batch``),
for the small-batch path and for the general path side by side (``small_batch_max = 0``
forces the general path), then a cProfile of the 1-sample call on each path (the
functions with most own time). ``--clock cpu`` times each call by its thread's CPU time
instead of the wall clock: on a machine shared with other work it leaves out the time the
process waits for a core (not what other work does to the caches).
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import time

import numpy as np

from app.data.simulator import simulate_dataset
from app.framework.registry import make_method
from bench.withdrawal import cpu_model

CLOCKS = {"wall": time.perf_counter, "cpu": time.thread_time}


def median_seconds(fn, repeats: int, clock=time.perf_counter) -> float:
    out = np.empty(repeats)
    for i in range(repeats):
        t = clock()
        fn()
        out[i] = clock() - t
    return float(np.median(out))


def with_novel(model, dataset, n_novel: int, seed: int = 0):
    """``model`` with ``n_novel`` zero-shot classes, half of them with one one-shot sample."""
    rng = np.random.default_rng(seed)
    taken = {tuple(v) for v in dataset.class_attributes.astype(int).tolist()}
    vectors: list[tuple[int, ...]] = []
    while len(vectors) < n_novel:
        v = tuple((rng.random(dataset.n_attributes) < 0.3).astype(int).tolist())
        if sum(v) and v not in taken:
            taken.add(v)
            vectors.append(v)
    names = [f"novel-{i}" for i in range(n_novel)]
    model = model.add_novel_classes(names, np.asarray(vectors, np.float32))
    for i in range(n_novel // 2):
        sample = dataset.samples[[(7 * i + 3) % len(dataset)]]
        model = model.add_one_shot(names[i], sample + rng.normal(0, 0.05, sample.shape))
    return model


def forcing_general(model):
    """A copy of ``model`` that always takes the general (large-batch) path."""
    import copy

    general = copy.copy(model)
    general.small_batch_max = 0
    return general


def profile(model, one: np.ndarray, calls: int = 2000, lines: int = 14) -> str:
    prof = cProfile.Profile()
    prof.enable()
    for _ in range(calls):
        model.recognize_batch(one)
    prof.disable()
    out = io.StringIO()
    pstats.Stats(prof, stream=out).sort_stats("tottime").print_stats(lines)
    body = out.getvalue().splitlines()
    start = next(i for i, line in enumerate(body) if line.strip().startswith("ncalls"))
    return "\n".join(body[start : start + lines + 1])


def measure(label: str, model, dataset, args) -> None:
    one = dataset.samples[:1]
    batch = dataset.samples[np.arange(args.batch) % len(dataset)]
    paths = {"small-batch path": model, "general path": forcing_general(model)}
    for m in paths.values():  # compile and warm the caches
        for _ in range(20):
            m.recognize_batch(one)
        m.recognize_batch(batch)
    print(f"\n== {label}: {len(model.registry.novel_names)} novel classes ({args.clock} clock)")
    # alternate the two paths so that load from elsewhere hits both alike
    single = {name: [] for name in paths}
    per_sample = {name: [] for name in paths}
    clock = CLOCKS[args.clock]
    for _ in range(3):
        for name, m in paths.items():
            single[name].append(
                median_seconds(lambda m=m: m.recognize_batch(one), args.repeats, clock)
            )
            per_sample[name].append(
                median_seconds(lambda m=m: m.recognize_batch(batch), args.batch_repeats, clock)
                / args.batch
            )
    for name in paths:
        s, b = min(single[name]), min(per_sample[name])
        print(
            f"{name:17s} ratio {s / b:5.2f}   1 sample {s * 1e6:7.1f} us   "
            f"batch of {args.batch} {b * 1e6:6.1f} us/sample"
        )
    for name, m in paths.items():
        print(f"\n-- cProfile of the 1-sample call, {name} (own time, 2,000 calls)")
        print(profile(m, one))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3000, help="1-sample calls per median")
    ap.add_argument("--batch", type=int, default=1024)
    ap.add_argument("--batch-repeats", type=int, default=15)
    ap.add_argument("--novel", type=int, default=6)
    ap.add_argument("--clock", choices=sorted(CLOCKS), default="wall", help="time per call")
    args = ap.parse_args()
    print(f"machine: {cpu_model()}; numpy {np.__version__}")
    dataset = simulate_dataset()
    model = make_method("best", seed=0).fit(dataset)
    measure("base model", model, dataset, args)
    if args.novel:
        measure("with novel classes", with_novel(model, dataset, args.novel), dataset, args)


if __name__ == "__main__":
    main()
