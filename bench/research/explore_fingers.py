"""Exploration bench (be3c8fd): the two BioTac fingers as augmentation, dev seeds only.

The paper doubled its data by treating the gripper's two BioTac sensors as two
samples. Our static features keep the fingers apart (``*_f0`` / ``*_f1``: 10 pairs per
exploratory procedure); the gripper closes symmetrically, so which finger touched
which side of an object carries little about the object, and attribute classifiers
learnt from 54 objects may be fitting that accident. Approaches, each a DAP variant
with ``best``'s logistic attribute classifiers on ``best``'s scaled inputs:

- ``swap``: train on every sample and its finger-swapped copy; score a test sample by
  the mean attribute logit of it and its swapped copy;
- ``swap-train``: the swapped copies in training only;
- ``sym``: replace each finger pair by its mean and absolute difference (invariant to
  the swap, and half as many finger inputs to fit);
- ``mean``: each finger pair by its mean only.

Reported alone, as a product with DAP, and with the out-of-object attribute AUC of the
known training objects (group k-fold over objects), on the novel objects' held-out
trials of development split seeds (never seed 0):

    .venv/bin/python bench/research/explore_fingers.py --seeds 1,2 --novel 6
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from dev_splits import add_split_arguments, print_zsl_means, tiny, zsl_cases
from sklearn.metrics import roc_auc_score
from sklearn.model_selection import GroupKFold

from app.data.phac2 import load_phac2
from app.methods.attributes import LinearAttributeModel, dap_log_scores
from app.methods.known import flatten

FEATURES = 47
FINGER_PAIRS = 10  # the first 20 features of each procedure alternate _f0, _f1


def finger_columns(phases: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flat column indices of finger 0, finger 1, and of the features shared by both."""
    f0, f1, shared = [], [], []
    for p in range(phases):
        base = p * FEATURES
        f0 += [base + 2 * i for i in range(FINGER_PAIRS)]
        f1 += [base + 2 * i + 1 for i in range(FINGER_PAIRS)]
        shared += list(range(base + 2 * FINGER_PAIRS, base + FEATURES))
    return np.array(f0), np.array(f1), np.array(shared)


def swapped(z: np.ndarray, cols) -> np.ndarray:
    f0, f1, _ = cols
    out = z.copy()
    out[:, f0], out[:, f1] = z[:, f1], z[:, f0]
    return out


def symmetric(z: np.ndarray, cols, with_difference: bool) -> np.ndarray:
    f0, f1, shared = cols
    parts = [(z[:, f0] + z[:, f1]) / 2]
    if with_difference:
        parts.append(np.abs(z[:, f0] - z[:, f1]))
    return np.hstack(parts + [z[:, shared]])


def logit(p: np.ndarray) -> np.ndarray:
    p = np.clip(p, 1e-9, 1 - 1e-9)
    return np.log(p) - np.log1p(-p)


def variant_proba(approach: str, z, targets, z_test, cols, C) -> np.ndarray:
    """(N_test, M) attribute probabilities of one variant."""
    if approach == "plain":
        return LinearAttributeModel.fit(z, targets, C).predict_proba(z_test)
    if approach in ("swap", "swap-train"):
        model = LinearAttributeModel.fit(
            np.vstack([z, swapped(z, cols)]), np.vstack([targets, targets]), C
        )
        if approach == "swap-train":
            return model.predict_proba(z_test)
        mean_logit = (
            logit(model.predict_proba(z_test)) + logit(model.predict_proba(swapped(z_test, cols)))
        ) / 2
        return 1 / (1 + np.exp(-mean_logit))
    if approach in ("sym", "mean"):
        with_difference = approach == "sym"
        return LinearAttributeModel.fit(
            symmetric(z, cols, with_difference), targets, C
        ).predict_proba(symmetric(z_test, cols, with_difference))
    raise SystemExit(f"unknown approach {approach!r}")


def out_of_object_auc(approach, z, y, targets, cols, C, folds) -> float:
    p = np.zeros(targets.shape)
    for fit, held in GroupKFold(folds).split(z, groups=y):
        p[held] = variant_proba(approach, z[fit], targets[fit], z[held], cols, C)
    aucs = [
        roc_auc_score(targets[:, j], p[:, j])
        for j in range(targets.shape[1])
        if 0 < targets[:, j].mean() < 1
    ]
    return float(np.mean(aucs))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    add_split_arguments(p)
    p.add_argument("--approaches", default="plain,swap,swap-train,sym,mean")
    p.add_argument("--C", type=float, default=0.1, help="attribute classifiers' C (best's)")
    p.add_argument("--clip", type=float, default=0.02, help="probability clip (best's)")
    p.add_argument("--folds", type=int, default=6, help="object folds for the out-of-object AUC")
    p.add_argument("--no-auc", action="store_true", help="skip the out-of-object AUC (faster)")
    args = tiny(p.parse_args(), folds=2)
    data = load_phac2(args.data)
    cols = finger_columns(flatten(data.samples[:1]).shape[1] // FEATURES)
    cases = []
    for case in zsl_cases(data, args):
        train = case.train
        targets = train.class_attributes[train.labels].astype(np.float64)
        prior = train.class_attributes.astype(np.float64).mean(0)
        for approach in args.approaches.split(","):
            proba = variant_proba(approach, case.z, targets, case.zt, cols, args.C)
            case.record(approach, dap_log_scores(proba, case.vectors, prior, args.clip))
            if not args.no_auc:
                case.row[f"auc_{approach}"] = out_of_object_auc(
                    approach, case.z, train.labels, targets, cols, args.C, args.folds
                )
        case.finish()
        cases.append(case)
    print_zsl_means(cases, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
