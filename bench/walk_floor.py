"""The floor under one sample's latency at scale: ``best``'s forest walk and neighbour
search alone, against the whole answer at 60 objects.

    .venv/bin/python -m bench.walk_floor [--sizes 60,3000] [--repeats 300] [--rounds 3]
                                         [--approximate-above N] [--out DIR]

For each size N, ``best`` (``by_procedure`` off: a complete sample is answered by the whole
model either way) is fitted on ``simulate_dataset(N, 10 trials)``; then, in turn for
``--rounds`` rounds, each on training samples of its own (at most ``--repeats``, none
taken twice while there are enough, so that no figure finds its samples' tree paths and
graph nodes in the caches where another left them), the median wall time of one sample's:

- ``answer_us``: ``recognize_batch`` (what ``bench.scale`` reports as recognise 1; one
  sample takes ``small_batch``'s scorer);
- ``general_us``: the same answer on the general path (``small_batch_max`` 0), the path
  one sample took through a neighbour index before 2026-11-27;
- ``walk_us``: the known-class forest's ``predict_proba`` on the scaled sample (the walk of
  every tree, the leaves' distributions summed): what any answer from this forest costs;
- ``search_us``: faiss's search of the HNSW graph for the sample's 3 nearest reference
  points (0 where the model compares exactly, below ``approximate_above``): what any
  answer with these novelty cues costs.

It prints a table with each figure divided by ``answer_us`` at the smallest size (the goal
is 3x at 30,000 objects) and writes ``walk_floor.json`` with the machine and the commit,
and ``walk_floor.png``, the figures against the number of objects beside the goal.
"""

from __future__ import annotations

import argparse
import copy
import functools
import json
import sys
import time
from pathlib import Path

import numpy as np

from bench.scale import finish_plot, machine, parse_sizes


def _median_us(fn, xs: np.ndarray) -> float:
    fn(xs[:1])
    times = []
    for i in range(len(xs)):
        t = time.perf_counter()
        fn(xs[i : i + 1])
        times.append(time.perf_counter() - t)
    return float(np.median(times)) * 1e6


def measure(n: int, repeats: int, rounds: int, approximate_above: int | None) -> dict:
    from app.data.simulator import simulate_dataset
    from app.framework.scaling import flatten
    from app.methods.best import BestRecognizer

    ds = simulate_dataset(n, 10, seed=0)
    options = {} if approximate_above is None else {"approximate_above": approximate_above}
    model = BestRecognizer(n_jobs=-1, by_procedure=False, **options).fit(ds)
    general = copy.copy(model)
    general.small_batch_max = 0
    cues = model.known_.cues_model
    f, dist = cues.forest, cues.distances
    graph = None if dist.index is None else dist.index.index  # faiss's HNSW graph alone

    def scaled(x: np.ndarray) -> np.ndarray:
        return cues.scaled(flatten(x)).astype(np.float32)

    # each figure's inputs, from samples of its own: a figure timed on the samples another
    # just took would find their trees' paths and graph nodes in the caches
    timed = {
        "answer_us": (lambda x: model.recognize_batch(x, 1), lambda x: x),
        "general_us": (lambda x: general.recognize_batch(x, 1), lambda x: x),
        "walk_us": (f.predict_proba, scaled),
    }
    if graph is not None:
        timed["search_us"] = (
            functools.partial(graph.search, k=3),
            lambda x: dist.coordinates(scaled(x) * cues.weights),
        )
    order = np.random.default_rng(0).permutation(len(ds))
    per = max(1, min(repeats, len(ds) // (len(timed) * rounds)))
    figures: dict[str, list[float]] = {k: [] for k in timed}
    for r in range(rounds):
        for j, (name, (fn, inputs)) in enumerate(timed.items()):
            rows = order[((r * len(timed) + j) * per + np.arange(per)) % len(order)]
            figures[name].append(_median_us(fn, inputs(ds.samples[rows])))
    return {
        "objects": n,
        "forest_nodes": f.n_nodes,
        "search_us": 0.0,
        **{k: float(np.median(v)) for k, v in figures.items()},
    }


def plot(records: list[dict], path: Path) -> None:
    """The figures of ``records`` against the number of objects, log-log, and the goal: 3x
    the answer at the smallest size."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["objects"] for r in records]
    fig, ax = plt.subplots(figsize=(8, 5.5))
    for key, label in (
        ("answer_us", "answer (small-batch path)"),
        ("general_us", "answer, general path"),
        ("walk_us", "forest walk alone"),
        ("search_us", "graph search alone"),
    ):
        pts = [(x, r[key]) for x, r in zip(n, records, strict=True) if r[key] > 0]
        if pts:
            ax.loglog(*zip(*pts, strict=True), "o-", label=label)
    floor = [r["walk_us"] + r["search_us"] for r in records]
    ax.loglog(n, floor, "k:", label="walk + search alone")
    ax.axhline(3 * records[0]["answer_us"], color="r", ls="--", label=f"goal: 3x at {n[0]}")
    finish_plot(
        fig,
        path,
        "known objects N",
        "µs for one sample",
        "best: one sample's answer against what its walk and search cost alone",
        legend_size=8,
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--sizes", default="60,3000")
    p.add_argument("--repeats", type=int, default=300)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument(
        "--approximate-above",
        type=int,
        default=None,
        help="best's approximate_above (default: best's own, 20000 samples)",
    )
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args(argv)
    sizes = parse_sizes(p, args.sizes)
    if args.repeats < 1 or args.rounds < 1:
        p.error("--repeats and --rounds must be 1 at least")
    if args.approximate_above is not None and args.approximate_above < 0:
        p.error("--approximate-above must be 0 or more")
    records = []
    for n in sizes:
        print(f"walk_floor: {n} objects ...", file=sys.stderr, flush=True)
        records.append(measure(n, args.repeats, args.rounds, args.approximate_above))
    base = records[0]["answer_us"]
    at = sizes[0]
    print(
        f"| objects | nodes | answer | general path | walk alone | search alone | "
        f"answer ÷ at {at} | walk + search ÷ answer at {at} |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in records:
        print(
            f"| {r['objects']:,} | {r['forest_nodes']:,} | {r['answer_us']:.0f} µs | "
            f"{r['general_us']:.0f} µs | {r['walk_us']:.0f} µs | {r['search_us']:.0f} µs | "
            f"{r['answer_us'] / base:.1f}x | {(r['walk_us'] + r['search_us']) / base:.1f}x |"
        )
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "walk_floor.json").write_text(
            json.dumps({"machine": machine(), "sizes": records}, indent=1)
        )
        plot(records, args.out / "walk_floor.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
