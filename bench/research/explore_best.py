"""Exploration bench for the ``best`` method on the real PHAC-2 features.

Runs the evaluation harness (``app.evaluation.protocol.evaluate``: the same
splits, whole-trial hold-out and figures as ``tactile-zsl evaluate``) for some
methods and parameter variants, on *development* split seeds, and prints the
mean figures side by side. Development happened on seeds 1 and 2 so that the
reported figures (seed 0 until 2026-11-24, seed 1000 since, ``tactile-zsl evaluate``)
were not the ones tuned on;
every method still tunes its own novelty threshold on validation objects carved
from the known set only.

    .venv/bin/python bench/research/explore_best.py --seeds 1,2 --novel 6
    .venv/bin/python bench/research/explore_best.py --variants 'best;best:shot_temperature=0.1' --seeds 1
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from dev_splits import add_split_arguments, split_seeds, tiny

from app.data.phac2 import load_phac2
from app.evaluation.protocol import FIGURES, evaluate


def parse_variant(spec: str) -> tuple[str, str, dict]:
    """'method' or 'method:key=value,key=value' -> (label, method, params)."""
    method, _, rest = spec.partition(":")
    params = {}
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        try:
            params[key] = json.loads(value)
        except json.JSONDecodeError:
            params[key] = value
    return spec, method, params


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--variants", default="best", help="';'-separated method[:k=v,...] specs")
    add_split_arguments(ap)
    ap.add_argument("--out", type=Path, default=None, help="write every run's results JSON here")
    args = tiny(ap.parse_args())

    dataset = load_phac2(args.data)
    variants = [parse_variant(s) for s in args.variants.split(";") if s.strip()]
    seeds = split_seeds(args)
    table: dict[str, dict[str, list[float]]] = {}
    timings: dict[str, list[float]] = {}
    dump = []
    for label, method, params in variants:
        for seed in seeds:
            t = time.perf_counter()
            res = evaluate(
                dataset,
                [method],
                n_novel=args.novel,
                n_splits=args.splits,
                seed=seed,
                method_params={method: params},
                progress=False,
            )
            entry = res["methods"][method]
            for f in FIGURES:
                table.setdefault(label, {}).setdefault(f, []).append(entry["mean"][f])
            fit = [d["timings"]["fit_s"] for d in entry["details"]]
            timings.setdefault(label, []).append(float(np.mean(fit)))
            dump.append({"variant": label, "seed": seed, "results": res})
            print(
                f"{label} seed {seed}: {time.perf_counter() - t:.0f}s", file=sys.stderr, flush=True
            )
    print(f"novel={args.novel} splits={args.splits} seeds={seeds}")
    print("variant".ljust(40) + "".join(f[:10].rjust(11) for f in FIGURES) + "    fit_s")
    for label, figs in table.items():
        row = "".join(
            f"{np.nanmean([v if v is not None else np.nan for v in figs[f]]):11.3f}"
            for f in FIGURES
        )
        print(label[:40].ljust(40) + row + f"{np.mean(timings[label]):9.1f}")
        if len(seeds) > 1:
            for i, seed in enumerate(seeds):
                row = "".join(
                    f"{np.nan if figs[f][i] is None else figs[f][i]:11.3f}" for f in FIGURES
                )
                print(f"  seed {seed}".ljust(40) + row + f"{timings[label][i]:9.1f}")
    if args.out:
        args.out.write_text(json.dumps(dump))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
