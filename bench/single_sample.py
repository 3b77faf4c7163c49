"""One sample in process: what each method's ``recognize_batch`` costs for 1 sample against
its batch-amortised cost per sample, where the 1-sample call spends its time, and the
methods the default (``auto``) chooses between side by side.

    .venv/bin/python -m bench.single_sample [--methods best,prototypes] [--repeats 3000]
                                            [--batch 1024] [--novel 6] [--clock wall|cpu]
                                            [--rounds 3] [--clients 32] [--seconds 2]
                                            [--json docs/results/single_sample/x.json]

Each of ``--methods`` (default ``best,prototypes``: ``auto`` chooses one of them, and
``prototypes`` on the embedded default) is fitted on the embedded default
(``simulate_dataset()``, seed 0), then, for a second model, given ``--novel`` zero-shot
classes (attribute vectors no known class has) of which half get one one-shot sample each.
First, side by side: the median seconds of a 1-sample call of each method, the methods
alternating call for call in ``--rounds`` rounds, and each method's over the first's (per
round: median and range), for the base models and those with novel classes. Then, for each
method and model, the ratio
(median seconds of a 1-sample call) / (median seconds of a ``--batch`` call / ``--batch``),
for the small-batch path and for the general path side by side (``small_batch_max = 0``
forces the general path), then a cProfile of the 1-sample call on each path (the
functions with most own time). ``--clock cpu`` times each call by its thread's CPU time
instead of the wall clock: on a machine shared with other work it leaves out the time the
process waits for a core (not what other work does to the caches).

The scorer's gain is printed per round (general path's 1-sample time over the small-batch
path's, median and range over the rounds), and, with ``--clients N`` (default 32; 0 skips
it), once more through the service's ``RecognitionBatcher``: N concurrent 1-sample requests
in one event loop, as the API process answers them (the batcher coalesces requests that
arrive during a pass, so passes hold several samples), each path for ``--seconds`` a round,
alternately; it prints requests a second on each path, their ratio, and the mean samples a
pass. ``--json`` writes the side-by-side figures and each path's 1-sample and batch
costs, with the machine.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import pstats
import time
from pathlib import Path

import numpy as np

from app.data.simulator import simulate_dataset
from app.framework.registry import make_method
from bench.withdrawal import cpu_model

CLOCKS = {"wall": time.perf_counter, "cpu": time.thread_time}
#: the code the figures come from: the methods, the framework, the simulator, the batcher
CODE = ("app/methods", "app/framework", "app/data", "app/service/batcher.py", "bench")


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


def spread(num: list[float], den: list[float]) -> str:
    """Median and range of the per-round ratios num[i] / den[i]."""
    r = np.asarray(num) / np.asarray(den)
    return f"{np.median(r):.2f}x (rounds {r.min():.2f}-{r.max():.2f}, n={len(r)})"


def through_batcher(model, one: np.ndarray, clients: int, seconds: float):
    """(requests a second, mean samples a pass) of ``clients`` concurrent 1-sample requests
    through the service's ``RecognitionBatcher`` on ``model``, for ``seconds``."""
    import asyncio
    from types import SimpleNamespace

    from app.service.batcher import RecognitionBatcher

    passes: list[int] = []

    def recognize_batch(x, top_k, **options):
        passes.append(len(x))
        return model.recognize_batch(x, top_k, **options)

    loaded = SimpleNamespace(recognizer=SimpleNamespace(recognize_batch=recognize_batch))

    async def run() -> tuple[int, float]:
        batcher, done = RecognitionBatcher(), 0
        start = time.perf_counter()
        stop = start + seconds

        async def client() -> None:
            nonlocal done
            while time.perf_counter() < stop:
                await batcher.recognize(loaded, one, 3)
                done += 1

        await asyncio.gather(*(client() for _ in range(clients)))
        return done, time.perf_counter() - start

    done, elapsed = asyncio.run(run())
    return done / elapsed, float(np.mean(passes))


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
    print(
        f"\n== {model.method}, {label}: {len(model.registry.novel_names)} novel classes "
        f"({args.clock} clock)"
    )
    # alternate the two paths so that load from elsewhere hits both alike
    single = {name: [] for name in paths}
    per_sample = {name: [] for name in paths}
    clock = CLOCKS[args.clock]
    for _ in range(args.rounds):
        for name, m in paths.items():
            single[name].append(
                median_seconds(lambda m=m: m.recognize_batch(one), args.repeats, clock)
            )
            per_sample[name].append(
                median_seconds(lambda m=m: m.recognize_batch(batch), args.batch_repeats, clock)
                / args.batch
            )
    figures: dict = {}
    for name in paths:
        s, b = min(single[name]), min(per_sample[name])
        figures[name] = {"one_us": s * 1e6, "per_sample_in_batch_us": b * 1e6, "ratio": s / b}
        print(
            f"{name:17s} ratio {s / b:5.2f}   1 sample {s * 1e6:7.1f} us   "
            f"batch of {args.batch} {b * 1e6:6.1f} us/sample"
        )
    small, general = paths
    print(
        "scorer gain, 1 sample (general / small-batch): " + spread(single[general], single[small])
    )
    if args.clients:
        rates = {name: [] for name in paths}
        sizes = {name: [] for name in paths}
        for _ in range(args.rounds):
            for name, m in paths.items():
                rate, size = through_batcher(m, one, args.clients, args.seconds)
                rates[name].append(rate)
                sizes[name].append(size)
        for name in paths:
            print(
                f"{name:17s} through the batcher, {args.clients} clients: "
                f"{np.median(rates[name]):7.0f} requests/s, "
                f"{np.mean(sizes[name]):4.1f} samples a pass"
            )
        print(
            "scorer gain through the batcher (small-batch / general requests/s): "
            + spread(rates[small], rates[general])
        )
    for name, m in paths.items():
        print(f"\n-- cProfile of the 1-sample call, {name} (own time, 2,000 calls)")
        print(profile(m, one))
    return figures


def side_by_side(label: str, models: dict, dataset, args) -> dict:
    """Median seconds of one sample's ``recognize_batch`` of each model, the models taking
    turns call for call within each of ``--rounds`` rounds (so that load from elsewhere
    hits them alike), and each one's over the first model's."""
    one = dataset.samples[:1]
    clock = CLOCKS[args.clock]
    for m in models.values():
        for _ in range(50):
            m.recognize_batch(one)
    times = {name: np.empty(args.repeats) for name in models}
    medians: dict[str, list[float]] = {name: [] for name in models}
    for _ in range(args.rounds):
        for i in range(args.repeats):
            for name, m in models.items():
                t = clock()
                m.recognize_batch(one)
                times[name][i] = clock() - t
        for name in models:
            medians[name].append(float(np.median(times[name])))
    first = next(iter(models))
    print(f"\n== side by side, {label}: 1 sample in process ({args.clock} clock)")
    out: dict = {"one_us": {}, "ratio_to_" + first: {}}
    for name in models:
        us = [v * 1e6 for v in medians[name]]
        r = np.asarray(medians[name]) / np.asarray(medians[first])
        out["one_us"][name] = float(np.median(us))
        out["ratio_to_" + first][name] = {
            "median": float(np.median(r)),
            "min": float(r.min()),
            "max": float(r.max()),
        }
        print(
            f"{name:12s} 1 sample {np.median(us):7.1f} us (rounds {min(us):.1f}-{max(us):.1f})"
            f"   over {first}: {spread(medians[name], medians[first])}"
        )
    return out


def _key(label: str) -> str:
    return label.replace(" ", "_").replace("-", "_")


def code_and_machine() -> dict:
    """``bench.scale.machine()`` with the CPU's name, and ``dirty`` over the code this bench
    runs (``CODE``; ``changed_elsewhere``: the other tracked files that differed from HEAD,
    on a tree others edit)."""
    import subprocess

    from bench.scale import machine

    def changed(*paths: str) -> list[str]:
        out = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", *paths],
            capture_output=True,
            text=True,
        ).stdout
        return [line[3:] for line in out.splitlines() if line]

    mine, every = changed(*CODE), changed()
    return {
        **machine(),
        "cpu": cpu_model(),
        "dirty": bool(mine),
        "changed": mine,
        "changed_elsewhere": [c for c in every if c not in mine],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--methods", default="best,prototypes", help="comma-separated, first: base")
    ap.add_argument("--repeats", type=int, default=3000, help="1-sample calls per median")
    ap.add_argument("--batch", type=int, default=1024)
    ap.add_argument("--batch-repeats", type=int, default=15)
    ap.add_argument("--novel", type=int, default=6)
    ap.add_argument("--clock", choices=sorted(CLOCKS), default="wall", help="time per call")
    ap.add_argument("--rounds", type=int, default=3, help="alternating rounds of each path")
    ap.add_argument("--clients", type=int, default=32, help="concurrent requests (0: none)")
    ap.add_argument("--seconds", type=float, default=2.0, help="each batcher phase")
    ap.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = ap.parse_args()
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    print(f"machine: {cpu_model()}; numpy {np.__version__}")
    dataset = simulate_dataset()
    models = {m: make_method(m, seed=0).fit(dataset) for m in methods}
    groups = {"base model": models}
    if args.novel:
        groups["with novel classes"] = {
            m: with_novel(model, dataset, args.novel) for m, model in models.items()
        }
    options = {**vars(args), "json": None if args.json is None else str(args.json)}
    report: dict = {"machine": code_and_machine(), "numpy": np.__version__, "args": options}
    # keys without spaces: docs/BENCHMARKS.md links a figure by its key path
    report["side_by_side"] = {
        _key(label): side_by_side(label, group, dataset, args) for label, group in groups.items()
    }
    report["paths"] = {
        _key(label): {
            m: {_key(path): v for path, v in measure(label, model, dataset, args).items()}
            for m, model in group.items()
        }
        for label, group in groups.items()
    }
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=2) + "\n")
        print(f"\nwrote {args.json}")


if __name__ == "__main__":
    main()
