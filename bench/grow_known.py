"""Promotion without a refit against a full fit, on the simulator.

    .venv/bin/python -m bench.grow_known [--seeds 3] [--objects 40] [--promoted 4]
                                         [--trees 50] [--json PATH]

For each seed: ``simulate_dataset(objects, 10 trials)``, 8 training and 2 held-out trials per
object; ``best`` fitted on all but the last ``--promoted`` objects, which are then promoted
one at a time (``with_known_samples``, as the service does), against ``best`` fitted on all
of them. Reported: held-out accuracy among the known objects, overall and on the promoted
objects' trials, for both, and their means over the seeds. tests/methods/test_grow_known.py
holds the bounds docs/BENCHMARKS.md states.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

TRAIN_TRIALS = 8


def split(seed: int, objects: int):
    """(dataset, training mask): the simulator's objects, 8 training and 2 held-out trials."""
    from app.data.simulator import simulate_dataset

    ds = simulate_dataset(objects, TRAIN_TRIALS + 2, seed=seed)
    rank = np.zeros(len(ds.labels), int)
    for c in range(objects):
        rows = np.flatnonzero(ds.labels == c)
        rank[rows] = np.arange(len(rows))
    return ds, rank < TRAIN_TRIALS


def promote(base, ds, train, classes):
    """``base`` with ``classes`` promoted one at a time, as the service makes them."""
    model = base
    for c in classes:
        name = ds.class_names[c]
        model = model.with_known_samples(
            {name: ds.samples[train & (ds.labels == c)]}, {name: ds.class_attributes[c]}
        )
    return model


def right_answers(model, ds, rows) -> np.ndarray:
    """Whether each sample ``rows`` is answered its own object among the known ones."""
    names = np.array(model.registry.known_names)
    found = names[model.known_proba(ds.samples[rows]).argmax(axis=1)]
    return found == np.array(ds.class_names)[ds.labels[rows]]


def compare(seeds: int, objects: int, promoted: int, trees: int) -> dict:
    from app.methods.best import BestRecognizer

    per_seed = []
    for seed in range(seeds):
        ds, train = split(seed, objects)
        old = np.arange(objects - promoted)
        params = {"seed": seed, "n_estimators": trees}
        base = BestRecognizer(**params).fit(
            ds.subset(np.flatnonzero(train & np.isin(ds.labels, old))).select_classes(old)
        )
        grown = promote(base, ds, train, range(objects - promoted, objects))
        full = BestRecognizer(**params).fit(ds.subset(np.flatnonzero(train)))
        held = np.flatnonzero(~train)
        new = ds.labels[held] >= objects - promoted
        row = {"seed": seed, "grown_samples": grown.metrics["n_grown_samples"]}
        for label, model in (("grown", grown), ("full", full)):
            right = right_answers(model, ds, held)
            row[f"{label}_all"] = float(right.mean())
            row[f"{label}_promoted"] = float(right[new].mean())
        row["same_classes"] = grown.registry.known_names == full.registry.known_names
        per_seed.append(row)
    figures = ("grown_all", "full_all", "grown_promoted", "full_promoted")
    return {
        "seeds": per_seed,
        "mean": {f: float(np.mean([r[f] for r in per_seed])) for f in figures},
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="bench.grow_known", description=__doc__.split("\n")[0])
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--objects", type=int, default=40)
    p.add_argument("--promoted", type=int, default=4)
    p.add_argument("--trees", type=int, default=50)
    p.add_argument("--json", type=Path)
    args = p.parse_args(argv)
    if args.seeds < 1 or args.trees < 1 or not 1 <= args.promoted <= args.objects - 2:
        p.error("--seeds and --trees must be positive, --promoted in 1 … objects - 2")
    report = compare(args.seeds, args.objects, args.promoted, args.trees)
    print("| seed | grown, all | full fit, all | grown, promoted | full fit, promoted |")
    print("| --- | --- | --- | --- | --- |")
    for r in [*report["seeds"], {"seed": "mean", **report["mean"]}]:
        print(
            f"| {r['seed']} | {r['grown_all']:.3f} | {r['full_all']:.3f} | "
            f"{r['grown_promoted']:.3f} | {r['full_promoted']:.3f} |"
        )
    if args.json:
        args.json.write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
