"""The forest's tree growers side by side: ``gini_trees`` (``best``'s default) against
scikit-learn's extra-trees regressor on 32-dim class codes (``forest_grower`` "sklearn").

    .venv/bin/python -m bench.grower [--objects 3000] [--trees 10] [--rounds 3]
                                     [--small-nodes 0,32,64,128,256] [--out DIR]

On ``simulate_dataset(N, 10 trials)``, robustly scaled as ``best`` scales it, for all the
features (a whole-model forest) and for one procedure's block of them (a per-procedure
forest): the median over ``--rounds`` of the wall time to grow ``--trees`` trees on one
thread, each grower in turn on the same inputs, and each forest's known-object accuracy on
one held-out trial per object (the others train). Growing alone: the leaves' class shares
and flattening, which both growers share, are not timed. Then the compiled grower again for
each of ``--small-nodes`` (``grow_trees``' ``small_node``: nodes of at most that many
samples grown from a copy of their own; 0 none), which is how its default was chosen.
Prints both tables, with the ratio sklearn ÷ gini, and writes ``grower.json`` with the
machine and the commit.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from bench.featurize import median_ms
from bench.scale import machine


def measure(n_objects: int, trees: int, rounds: int, small_nodes: list[int]) -> list[dict]:
    from sklearn.ensemble import ExtraTreesRegressor

    from app.data.simulator import simulate_dataset
    from app.framework.scaling import RobustInputScaler, flatten
    from app.methods.forest import FlatForest
    from app.methods.gini_trees import SMALL_NODE, grow_trees

    ds = simulate_dataset(n_objects, 10, seed=0)
    test = ds.trials % 10 == 9
    y = ds.labels
    blocks = {"all": flatten(ds.samples)}
    if len(ds.procedures) >= 2:
        blocks[ds.procedures[0]] = flatten(ds.procedure_view(0).samples)
    list(grow_trees(blocks["all"][:200], y[:200], ds.n_classes, 1, "sqrt", 0))  # compile
    out = []
    for name, x in blocks.items():
        z = RobustInputScaler().fit(x[~test]).transform(x).astype(np.float32)
        train, labels = z[~test], y[~test]
        codes = np.random.default_rng(0).standard_normal((ds.n_classes, 32))[labels]
        record = {"objects": n_objects, "features": name, "dims": z.shape[1], "trees": trees}

        def gini(small_node: int, train=train, labels=labels) -> float:
            return 1e-3 * median_ms(
                lambda: list(
                    grow_trees(train, labels, ds.n_classes, trees, "sqrt", 0, 1, small_node)
                ),
                rounds,
            )

        record["gini_s"] = gini(SMALL_NODE)
        record["sklearn_s"] = 1e-3 * median_ms(
            lambda train=train, codes=codes: ExtraTreesRegressor(
                trees, max_features="sqrt", random_state=0, n_jobs=1
            ).fit(train, codes),
            rounds,
        )
        for grower in ("gini", "sklearn"):
            forest = FlatForest.grow(train, labels, ds.n_classes, trees, "sqrt", 0, 1, grower)
            hit = forest.predict_proba(z[test]).argmax(axis=1) == y[test]
            record[f"{grower}_acc"] = float(hit.mean())
        record["gini_by_small_node_s"] = {str(k): gini(k) for k in small_nodes}
        out.append(record)
        print(f"grower: {name} done", file=sys.stderr, flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--objects", type=int, default=3000)
    p.add_argument("--trees", type=int, default=10)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--small-nodes", default="0,32,64,128,256")
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args(argv)
    if args.objects < 2 or args.trees < 1 or args.rounds < 1:
        p.error("--objects must be 2 at least, --trees and --rounds 1 at least")
    try:
        small_nodes = [int(v) for v in args.small_nodes.split(",") if v.strip()]
    except ValueError:
        p.error(f"--small-nodes must be integers, got {args.small_nodes!r}")
    if any(k < 0 for k in small_nodes):
        p.error("--small-nodes must be 0 or more")
    records = measure(args.objects, args.trees, args.rounds, small_nodes)
    print(
        f"| features | gini, ms a tree | sklearn codes, ms a tree | sklearn ÷ gini | "
        f"accuracy, gini / sklearn ({args.trees} trees) |"
    )
    print("| --- | --- | --- | --- | --- |")
    for r in records:
        print(
            f"| {r['features']} ({r['dims']}) | {r['gini_s'] / r['trees'] * 1e3:.0f} | "
            f"{r['sklearn_s'] / r['trees'] * 1e3:.0f} | {r['sklearn_s'] / r['gini_s']:.2f}x | "
            f"{r['gini_acc']:.3f} / {r['sklearn_acc']:.3f} |"
        )
    if small_nodes:
        print("\n| features | " + " | ".join(f"small_node {k}" for k in small_nodes) + " |")
        print("| --- |" + " --- |" * len(small_nodes))
        for r in records:
            per = r["gini_by_small_node_s"]
            ms = [f"{per[str(k)] / r['trees'] * 1e3:.0f} ms" for k in small_nodes]
            print(f"| {r['features']} ({r['dims']}) | " + " | ".join(ms) + " |")
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "grower.json").write_text(
            json.dumps({"machine": machine(), "records": records}, indent=1)
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
