"""A backlog of promotions without a refit: one sample's recognition by ``prototypes`` after
N promotions learnt into its known part (``with_known_samples``, the service's
``KNOWN_GROWN`` rebuild), against the same model with none, side by side in one run.

    .venv/bin/python -m bench.grown_backlog [--objects 30000] [--promoted N] [--trials 4]
                                            [--per-round 20] [--samples 300] [--seed 0]
                                            [--omp-threads 1]
                                            [--out docs/results/grown_backlog/NAME.json]

``simulate_dataset(objects, trials, seed)``; ``prototypes`` (its defaults) is fitted on all
but the last ``--promoted`` objects (default a fifth of them: the service's
``TACTILE_GROW_FRACTION`` of 0.25 lets that many be learnt before a refit), which are then
promoted ``--per-round`` at a time (a retrain round learns every class promoted since the
last one), each by all of its trials. Three models answer: ``none`` (the fit), ``grown``
(the promotions, as the service learns them: added prototypes beside the faiss index until
``PrototypeSearch.fold_above`` of them wait, then folded into a copy of it) and
``brute_force`` (the same promotions, never folded: every added prototype searched
exactly, as before 2026-11-28). faiss runs on ``--omp-threads`` OpenMP threads (default 1:
on a loaded 2-core machine faiss's default of one thread per core made a single sample's
distances take 18.7 ms instead of 0.23 ms, which hides what is measured). Timed:
``recognize_batch`` of one sample, ``--samples``
different samples (one trial of each of as many objects, drawn among all of them), the
three models in turn on each sample, so that all see the same machine load; medians, and
the ratios of the medians to ``none``'s. Also recorded: each model's prototypes, how many
of them wait beside the index, how often ``grown`` and ``brute_force`` answer the same top
class, and how often each answers the sample's own object.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from pathlib import Path

import numpy as np

from bench.scale import machine


def grown(base, ds, classes: np.ndarray, per_round: int, fold: bool):
    """``base`` with ``classes`` promoted ``per_round`` at a time; ``fold`` False: its search
    never folds added prototypes into the index."""
    model = base
    if not fold:
        model = copy.copy(base)
        model.search_ = copy.copy(base.search_)
        model.search_.fold_above = sys.maxsize
    for lo in range(0, len(classes), per_round):
        chunk = classes[lo : lo + per_round]
        samples = {ds.class_names[c]: ds.samples[ds.labels == c] for c in chunk}
        vectors = {ds.class_names[c]: ds.class_attributes[c] for c in chunk}
        model = model.with_known_samples(samples, vectors)
    return model


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--objects", type=int, default=30000, help="simulated objects in all")
    p.add_argument("--promoted", type=int, default=None, help="default: objects // 5")
    p.add_argument("--trials", type=int, default=4, help="trials (samples) per object")
    p.add_argument("--per-round", type=int, default=20, help="promotions learnt at a time")
    p.add_argument("--samples", type=int, default=300, help="samples timed")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--omp-threads",
        type=int,
        default=1,
        help="faiss's OpenMP threads (0: its default, the machine's cores)",
    )
    p.add_argument("--out", type=Path, default=None, help="JSON file to write")
    args = p.parse_args(argv)
    promoted = args.objects // 5 if args.promoted is None else args.promoted
    if args.trials < 2:
        p.error("--trials must be at least 2 (the fit calibrates on held-out trials)")
    if not 0 <= promoted <= args.objects - 2:
        p.error("--promoted must leave at least 2 objects to fit on")
    if args.per_round < 1 or args.samples < 1:
        p.error("--per-round and --samples must be at least 1")

    import faiss

    from app.data.simulator import simulate_dataset
    from app.framework.registry import make_method

    if args.omp_threads > 0:
        faiss.omp_set_num_threads(args.omp_threads)

    ds = simulate_dataset(args.objects, args.trials, seed=args.seed)
    fitted = args.objects - promoted
    started = time.perf_counter()
    base = make_method("prototypes", seed=args.seed).fit(
        ds.subset(np.flatnonzero(ds.labels < fitted)).select_classes(np.arange(fitted))
    )
    fit_s = time.perf_counter() - started
    classes = np.arange(fitted, args.objects)
    models = {"none": base}
    grow_s = {}
    for name, fold in (("grown", True), ("brute_force", False)):
        started = time.perf_counter()
        models[name] = grown(base, ds, classes, args.per_round, fold) if promoted else base
        grow_s[name] = time.perf_counter() - started

    rng = np.random.default_rng(args.seed + 1)
    picked = rng.choice(args.objects, min(args.samples, args.objects), replace=False)
    rows = [np.flatnonzero(ds.labels == c)[0] for c in picked]
    for model in models.values():  # once, untimed: first calls build caches
        model.recognize_batch(ds.samples[rows[0]][None])
    times: dict[str, list[float]] = {name: [] for name in models}
    agree, right = 0, {name: 0 for name in models}
    for row in rows:
        one = ds.samples[row][None]
        answers = {}
        for name, model in models.items():
            t = time.perf_counter()
            answers[name] = model.recognize_batch(one)
            times[name].append(time.perf_counter() - t)
        top = {name: int(a.top_index[0, 0]) for name, a in answers.items()}
        agree += int(top["grown"] == top["brute_force"])
        for name, model in models.items():
            names = model.registry.known_names + model.registry.novel_names
            right[name] += int(names[top[name]] == ds.class_names[ds.labels[row]])
    medians = {name: float(np.median(t)) for name, t in times.items()}
    report = {
        "what": "one sample's recognize_batch by prototypes after N promotions without a refit",
        "command": "python -m bench.grown_backlog " + " ".join(argv or sys.argv[1:]),
        "objects": args.objects,
        "fitted_objects": fitted,
        "promoted": promoted,
        "trials": args.trials,
        "per_round": args.per_round,
        "samples_timed": len(rows),
        "fit_s": round(fit_s, 1),
        "promote_all_s": {k: round(v, 2) for k, v in grow_s.items()},
        "prototypes": {k: len(m.search_) for k, m in models.items()},
        "beside_the_index": {k: len(m.search_.extra) for k, m in models.items()},
        "exact_search": bool(base.search_.exact),
        "fold_above": models["grown"].search_.fold_above,
        "one_sample_us": {k: round(v * 1e6, 1) for k, v in medians.items()},
        "ratio_to_none": {k: round(v / medians["none"], 3) for k, v in medians.items()},
        "top1_same_grown_and_brute_force": agree / len(rows),
        "top1_right": {k: v / len(rows) for k, v in right.items()},
        "omp_threads": args.omp_threads,
        "machine": machine(),
    }
    text = json.dumps(report, indent=2)
    print(text)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
