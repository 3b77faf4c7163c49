"""A promotion's small trees: ``app.methods.leaf_trees.grow_leaf`` against scikit-learn's
``ExtraTreeClassifier.fit`` (``check_input=False``, parameter validation skipped: how
promotions grew them before 237d6cd), side by side on the same leaf-sized samples.

    .venv/bin/python -m bench.leaf_trees [--trees 2000] [--samples 12] [--features 960]

Each round grows ``--trees`` trees with each, alternately, on ``--samples`` random samples
of 3 labels and ``--features`` features (the simulator's width; a reached leaf holds a
few samples). It prints the median time per tree of each over 3 rounds and their ratio.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def per_tree_us(grow, xs, ys) -> float:
    t = time.perf_counter()
    for seed, (x, y) in enumerate(zip(xs, ys, strict=True)):
        grow(x, y, seed)
    return (time.perf_counter() - t) / len(xs) * 1e6


def main(argv: list[str] | None = None) -> int:
    import sklearn
    from sklearn.tree import ExtraTreeClassifier

    from app.methods.leaf_trees import grow_leaf

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--trees", type=int, default=2000)
    p.add_argument("--samples", type=int, default=12)
    p.add_argument("--features", type=int, default=960)
    args = p.parse_args(argv)
    if args.trees < 1 or args.samples < 2 or args.features < 1:
        p.error("--trees must be at least 1, --samples at least 2, --features at least 1")
    rng = np.random.default_rng(0)
    xs = rng.normal(size=(args.trees, args.samples, args.features)).astype(np.float32)
    ys = rng.integers(0, 3, (args.trees, args.samples))

    def ours(x, y, seed):
        grow_leaf(x, y, "sqrt", seed)

    def theirs(x, y, seed):
        with sklearn.config_context(skip_parameter_validation=True):
            ExtraTreeClassifier(max_features="sqrt", random_state=seed).fit(x, y, check_input=False)

    ours(xs[0], ys[0], 0)  # compiled once, outside the timing
    rounds = {"leaf_trees": [], "scikit-learn": []}
    for _ in range(3):
        rounds["leaf_trees"].append(per_tree_us(ours, xs, ys))
        rounds["scikit-learn"].append(per_tree_us(theirs, xs, ys))
    med = {k: float(np.median(v)) for k, v in rounds.items()}
    print(f"scikit-learn {sklearn.__version__}, {args.samples} samples x {args.features} features")
    for k, v in med.items():
        print(f"{k}: {v:.1f} us a tree")
    print(f"scikit-learn / leaf_trees: {med['scikit-learn'] / med['leaf_trees']:.1f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
