"""How well ``POST /v1/describe`` describes objects the model never touched, on real PHAC-2.

    .venv/bin/python bench/describe_quality.py --seeds 0 --novel 6 --out docs/results/describe

For each split of ``tactile-zsl evaluate``'s protocol (the same seeds, novel objects and
held-out trials), ``best`` is fitted on the known objects' training trials with the
service's parameters, and every test trial of the novel objects is described: the
probability of each attribute (``attribute_proba``) and the suggestion the service makes
(attributes above 0.5, at least the most probable one). Nothing is tuned: the 0.5 rule is
fixed in the service. Measured against each novel object's PHAC-2 adjectives:

- per-attribute AUC over all novel test trials of all splits (how well each attribute
  classifier ranks touches of objects it never saw), drawn as ``attribute_auc.png``;
- per touch, the suggestion's precision and recall and how often it is exactly right;
- the same for a suggestion from an object's mean probability over its test trials (what
  ``?same_object=true`` answers for several touches of one object).

Progress goes to stderr; one JSON report to stdout and to ``--out``/describe.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from app.api.routes.describe import suggestion  # the service's rule
from app.data.phac2 import load_phac2
from app.evaluation.protocol import make_recognizer
from app.evaluation.splits import make_zsl_splits
from app.framework.registry import DEFAULT_METHOD

DEFAULT_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "phac2"


def agreement(suggested: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    hits = (suggested & truth).sum(axis=1)
    return {
        "precision": round(float(np.mean(hits / suggested.sum(axis=1))), 3),
        "recall": round(float(np.mean(hits / np.maximum(truth.sum(axis=1), 1))), 3),
        "exact": round(float(np.mean((suggested == truth).all(axis=1))), 3),
        "mean_suggested": round(float(suggested.sum(axis=1).mean()), 2),
        "mean_true": round(float(truth.sum(axis=1).mean()), 2),
    }


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the PHAC-2 folder")
    ap.add_argument(
        "--seeds", default="1,2", help="comma-separated split seeds (0: the reported splits)"
    )
    ap.add_argument("--novel", type=int, default=6, help="novel objects per split")
    ap.add_argument("--splits", type=int, default=7, help="splits per seed")
    ap.add_argument("--out", type=Path, default=Path("docs/results/describe"))
    args = ap.parse_args()
    from sklearn.metrics import roc_auc_score

    dataset = load_phac2(args.data)
    names = list(dataset.attribute_names)
    probas, truths, object_probas, object_truths = [], [], [], []
    started = time.perf_counter()
    every_split = [
        (int(seed), split)
        for seed in args.seeds.split(",")
        for split in make_zsl_splits(dataset, args.novel, args.splits, int(seed))
    ]
    for seed, split in every_split:
        # fitted as evaluate fits it
        model = make_recognizer(DEFAULT_METHOD, None, seed).fit(split.train_dataset(dataset))
        idx = split.novel_test_idx
        proba = model.attribute_proba(dataset.samples[idx])
        truth = dataset.class_attributes[dataset.labels[idx]] > 0.5
        probas.append(proba)
        truths.append(truth)
        for cls in split.novel_classes:
            rows = dataset.labels[idx] == cls
            object_probas.append(proba[rows].mean(axis=0))
            object_truths.append(dataset.class_attributes[cls] > 0.5)
        print(
            f"seed {seed} split {split.index}: {len(idx)} touches of {len(split.novel_classes)} "
            f"novel objects described ({time.perf_counter() - started:.0f} s)",
            file=sys.stderr,
        )
    proba, truth = np.concatenate(probas), np.concatenate(truths)
    auc = {
        n: round(float(roc_auc_score(truth[:, j], proba[:, j])), 3)
        for j, n in enumerate(names)
        if 0 < truth[:, j].mean() < 1
    }
    report = {
        "command": " ".join(["bench/describe_quality.py", *sys.argv[1:]]),
        "seeds": args.seeds,
        "novel": args.novel,
        "splits": args.splits,
        "touches": int(len(proba)),
        "objects": len(object_probas),
        "mean_attribute_auc": round(float(np.mean(list(auc.values()))), 3),
        "attribute_auc": dict(sorted(auc.items(), key=lambda kv: -kv[1])),
        "per_touch": agreement(suggestion(proba), truth),
        "per_object_from_its_touches": agreement(
            suggestion(np.stack(object_probas)), np.stack(object_truths)
        ),
        # the same rule on the attributes' frequencies alone, the same for every touch
        "per_touch_if_always_the_commonest": agreement(
            np.broadcast_to(suggestion(truth.mean(axis=0, keepdims=True)), truth.shape), truth
        ),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "describe.json").write_text(json.dumps(report, indent=2) + "\n")
    draw(auc, report["mean_attribute_auc"], args.out / "attribute_auc.png")
    print(json.dumps(report, indent=2))
    return 0


def draw(auc: dict[str, float], mean: float, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ordered = sorted(auc.items(), key=lambda kv: kv[1])
    fig, ax = plt.subplots(figsize=(6, 0.28 * len(ordered) + 1.2))
    ax.barh([n for n, _ in ordered], [v for _, v in ordered], color="tab:blue")
    ax.axvline(0.5, color="grey", linestyle=":", label="chance")
    ax.axvline(mean, color="tab:red", linestyle="--", label=f"mean {mean:.2f}")
    ax.set_xlim(0, 1)
    ax.set_xlabel("AUC on touches of objects the model never saw")
    ax.set_title("POST /v1/describe on PHAC-2: each attribute")
    ax.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
