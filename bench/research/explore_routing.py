"""Exploration bench: soft routing of the mixed known + novel decision, dev seeds only.

``best`` routes hard: a sample whose novelty score s exceeds the tuned threshold t goes
to the zero-shot classifier, any other to the known-class forest. Soft routing (in the
spirit of calibrated stacking, Chao et al. 2016) lets a confident classifier overrule a
borderline score: with q = sigmoid((s - t) / T), answer the novel class argmax p_novel
when q * max p_novel > (1 - q) * max p_known, else the known class argmax p_known.
T -> 0 is the hard rule. Prints gzsl_seen / gzsl_unseen / gzsl_h per temperature,
averaged over development splits (never seed 0, the reported one).

    .venv/bin/python bench/research/explore_routing.py --seeds 1,2 --novel 6
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np
from dev_splits import add_split_arguments, enrolled_best, splits, tiny

from app.data.phac2 import load_phac2
from app.evaluation import metrics


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    add_split_arguments(p)
    p.add_argument("--temperatures", default="0,0.01,0.02,0.05,0.1,0.2,0.5")
    args = tiny(p.parse_args())
    temps = [float(t) for t in args.temperatures.split(",")]
    data = load_phac2(args.data)
    per_t: dict[float, list[tuple[float, float, float]]] = {t: [] for t in temps}
    for seed, split in splits(data, args):
        train = split.train_dataset(data)
        model = enrolled_best(data, split)
        xk, xn = data.samples[split.known_test_idx], data.samples[split.novel_test_idx]
        names_k, names_n = list(train.class_names), list(split.novel_names)
        true = [names_k[j] for j in split.known_labels(data, split.known_test_idx)] + [
            names_n[j] for j in split.novel_labels(data, split.novel_test_idx)
        ]
        is_known = np.r_[np.ones(len(xk), bool), np.zeros(len(xn), bool)]
        score, p_known, p_novel = model._all_scores(
            model.validate_samples(np.concatenate([xk, xn]))
        )
        known_pick = np.asarray(names_k, object)[p_known.argmax(1)]
        novel_pick = np.asarray(names_n, object)[p_novel.argmax(1)]
        for t in temps:
            if t == 0:
                novel = score > model.novelty_threshold
            else:
                q = 1.0 / (1.0 + np.exp(-np.clip((score - model.novelty_threshold) / t, -50, 50)))
                novel = q * p_novel.max(1) > (1 - q) * p_known.max(1)
            pred = np.where(novel, novel_pick, known_pick)
            f = metrics.gzsl_figures(true, list(pred), is_known)
            per_t[t].append((f["gzsl_seen"], f["gzsl_unseen"], f["gzsl_h"]))
        print(f"seed {seed} split {split.index + 1} done", file=sys.stderr, flush=True)
    out = {
        str(t): dict(
            zip(
                ("gzsl_seen", "gzsl_unseen", "gzsl_h"),
                np.round(np.mean(v, axis=0), 3).tolist(),
                strict=True,
            )
        )
        for t, v in per_t.items()
    }
    print(json.dumps({"novel": args.novel, "seeds": args.seeds, "by_temperature": out}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
