"""Which candidate of ``auto`` to choose where no probe is possible: small catalogues.

A service that learns from a robot starts with a few classes of 2 enrolled samples each,
where ``auto``'s probe cannot hold a trial out (``app/methods/choice.py``). This fits
``best`` and ``prototypes`` on ``--samples`` single touches (each from its own trial) of
each of K classes and names every touch of the classes' other trials, on PHAC-2 (K
objects drawn at random) and on the simulator (K objects of its own), for each seed of
``--seeds`` (development seeds; the reported ones are never used here). It prints one JSON
report: per source and K, each method's mean accuracy and its standard error over seeds.

    .venv/bin/python bench/research/small_catalogue.py --data ../shared/data/phac2
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings

import numpy as np

from app.data.phac2 import load_phac2
from app.data.simulator import simulate_dataset
from app.framework.registry import make_method

METHODS = ("best", "prototypes")


def few_shot_split(ds, samples: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(train rows, test rows): one sample of each of ``samples`` trials of every class to
    fit on, every sample of its other trials to name."""
    train, test = [], []
    for c in range(ds.n_classes):
        trials = rng.permutation(np.unique(ds.trials[ds.labels == c]))
        for i, t in enumerate(trials):
            rows = np.flatnonzero((ds.labels == c) & (ds.trials == t))
            (train.extend(rows[:1]) if i < samples else test.extend(rows))
    return np.array(train), np.array(test)


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--data", default="../shared/data/phac2", help="PHAC-2 folder")
    ap.add_argument("--classes", default="2,3,5", help="catalogue sizes K, comma-separated")
    ap.add_argument("--samples", type=int, default=2, help="enrolled samples a class")
    ap.add_argument("--seeds", default="101-108", help="development seeds, a range a-b")
    ap.add_argument("--tiny", action="store_true", help="one seed, K=2: a smoke run")
    args = ap.parse_args()
    first, _, last = args.seeds.partition("-")
    seeds = list(range(int(first), int(last or first) + 1))
    sizes = [int(k) for k in args.classes.split(",")]
    if args.tiny:
        seeds, sizes = seeds[:1], [2]
    warnings.filterwarnings("ignore")
    phac2 = load_phac2(args.data)
    report: dict = {"samples": args.samples, "seeds": seeds, "accuracy": {}}
    for source in ("phac2", "simulator"):
        for k in sizes:
            accs: dict[str, list[float]] = {m: [] for m in METHODS}
            for seed in seeds:
                rng = np.random.default_rng(seed)
                if source == "simulator":
                    ds = simulate_dataset(k, 10, seed=seed)
                else:
                    ds = phac2.select_classes(rng.choice(phac2.n_classes, k, replace=False))
                train, test = few_shot_split(ds, args.samples, rng)
                for m in METHODS:
                    model = make_method(m, seed=seed).fit(ds.subset(train))
                    named = model.known_proba(ds.samples[test]).argmax(axis=1)
                    accs[m].append(float(np.mean(named == ds.labels[test])))
            report["accuracy"][f"{source} K={k}"] = {
                m: {"mean": float(np.mean(v)), "sem": float(np.std(v) / np.sqrt(len(v)))}
                for m, v in accs.items()
            }
            print(f"{source} K={k}: {report['accuracy'][f'{source} K={k}']}", file=sys.stderr)
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
