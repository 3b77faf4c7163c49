"""Novelty cues beyond ``best``'s, on development split seeds (issue 5).

``best`` scores novelty by the forest's 1 − max-probability plus two distance cues
(AUROC ~0.98). The targets need both ``nd_known_kept`` and ``nd_novel_detected`` ≥ 0.95,
which no threshold reaches with that score (``bench/novelty_bound.py``). This measures,
per split, the AUROC and the oracle balance (the best min(kept, detected) over all
thresholds, chosen on the test samples: an upper bound, not a result) of candidate
scores, each a diagnostic on development seeds only:

- ``best``: the deployed score;
- ``phases``: disagreement of one extra-trees forest per exploratory procedure
  (squeeze, hold, slide, move down): −log of the largest geometric mean over classes
  of the four forests' posteriors. A known object should feel like the same object in
  every procedure; a novel one may resemble different known objects in each;
- ``best+phases·w``: the sum, the phase cue weighted by ``w``;
- ``proximity``: 1 − the largest forest proximity (share of trees in which two samples
  end in the same leaf) between the sample and any training trial: a similarity learned
  by the forest rather than a distance in the scaled feature space;
- ``best+proximity·w``: the sum, the proximity cue weighted by 10·w (it spans 0–1, the
  phase cue about 0–7).

Measured (session 5, seeds 1–2, 14 splits, 6 novel; AUROC / oracle balance): best
0.9731 / 0.9233; phases alone 0.9573 / 0.8922, added at w = 0.2 0.9743 / 0.9272;
proximity alone 0.9477 / 0.8750, added at best 0.9735 / 0.9246. Neither is adopted: the
gains are a tenth of the split-to-split spread, and the bound stays far below 0.95.

    .venv/bin/python bench/explore_novelty.py --seeds 1,2 --novel 6
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from sklearn.ensemble import ExtraTreesClassifier
from sklearn.metrics import roc_auc_score

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from dev_splits import add_split_arguments, splits  # noqa: E402
from novelty_bound import oracle_balance  # noqa: E402

from app.data.phac2 import load_phac2  # noqa: E402
from app.framework.registry import make_method  # noqa: E402

WEIGHTS = (0.02, 0.05, 0.1, 0.2)
PHASES = 4  # PHAC-2's exploratory procedures, in the order of the flat features


def phase_disagreement(train_x, train_y, test_x, n_trees: int, seed: int) -> np.ndarray:
    """−log max_c (Π_p P_p(c | x))^(1/P) over the procedures p (axis 1 of the samples)."""
    log_post = 0.0
    for p in range(train_x.shape[1]):
        forest = ExtraTreesClassifier(n_trees, random_state=seed + p, n_jobs=1)
        forest.fit(train_x[:, p], train_y)
        log_post = log_post + np.log(forest.predict_proba(test_x[:, p]) + 1e-3)
    return -np.max(log_post / train_x.shape[1], axis=1)


def proximity_novelty(train_x, train_y, test_x, n_trees: int, seed: int) -> np.ndarray:
    forest = ExtraTreesClassifier(n_trees, random_state=seed, n_jobs=1).fit(train_x, train_y)
    train_leaves, test_leaves = forest.apply(train_x), forest.apply(test_x)  # (N, trees)
    shared = (test_leaves[:, None, :] == train_leaves[None, :, :]).mean(axis=2)
    return 1 - shared.max(axis=1)


def by_phase(samples: np.ndarray) -> np.ndarray:
    """(N, 188) → (N, 4 procedures, 47 features); signed log1p tames the heavy tails (trees
    need nothing more)."""
    return (np.sign(samples) * np.log1p(np.abs(samples))).reshape(len(samples), PHASES, -1)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_split_arguments(ap)
    ap.add_argument("--trees", type=int, default=100)
    args = ap.parse_args()
    dataset = load_phac2(args.data)
    names = ["best", "phases"] + [f"best+phases*{w}" for w in WEIGHTS] + ["proximity"] + [
        f"best+proximity*{w}" for w in WEIGHTS]
    auroc: dict[str, list[float]] = {n: [] for n in names}
    oracle: dict[str, list[float]] = {n: [] for n in names}
    print(f"{args.novel} novel objects, seeds {args.seeds}: AUROC / oracle balance per split")
    for seed, split in splits(dataset, args, development_only=True):
        train = split.train_dataset(dataset)
        model = make_method("best", seed=0).fit(train)
        idx = np.concatenate([split.known_test_idx, split.novel_test_idx])
        is_novel = np.r_[np.zeros(len(split.known_test_idx)), np.ones(len(split.novel_test_idx))]
        x = dataset.samples[idx]
        scores = {"best": model.novelty_score(x),
                  "phases": phase_disagreement(by_phase(train.samples), train.labels, by_phase(x),
                                               args.trees, seed)}
        flat = lambda a: by_phase(a).reshape(len(a), -1)  # noqa: E731
        scores["proximity"] = proximity_novelty(flat(train.samples), train.labels, flat(x), args.trees, seed)
        for w in WEIGHTS:
            scores[f"best+phases*{w}"] = scores["best"] + w * scores["phases"]
            scores[f"best+proximity*{w}"] = scores["best"] + 10 * w * scores["proximity"]
        line = []
        for n in names:
            auroc[n].append(roc_auc_score(is_novel, scores[n]))
            oracle[n].append(oracle_balance(scores[n][is_novel == 0], scores[n][is_novel == 1]))
            line.append(f"{auroc[n][-1]:.3f}/{oracle[n][-1]:.3f}")
        print(f"seed {seed} split {split.index + 1}: " + "  ".join(line), flush=True)
    print("\nmean over splits (AUROC / oracle balance):")
    for n in names:
        print(f"  {n:18s} {np.mean(auroc[n]):.4f} / {np.mean(oracle[n]):.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
