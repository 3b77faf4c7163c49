"""The evaluation protocol of Sect. VI, run for several methods on the same splits.

For every split (see ``splits``) and every method:

1. fit on the known objects' training trials; the method tunes its novelty
   threshold itself by the Sect. VI-B protocol and exposes ``novelty_tuning``;
2. ``known_acc``: argmax of ``known_proba`` on the known objects' held-out trials
   (Table III);
3. ``nd_known_kept`` / ``nd_val_novel``: the method's own tuning figures at its
   threshold (Table II, columns X_te and X_val); ``nd_novel_detected``: fraction
   of the novel objects' test samples whose novelty score is above the threshold
   (Table II, column X_Z); ``nd_auroc``: AUROC of the novelty score, held-out
   known trials against novel test samples;
4. ``zsl``: ``add_novel_classes`` with the novel objects' names and attribute
   vectors, then argmax of ``novel_proba`` on the novel test samples (Tables V-VII);
5. ``osl``: the one-shot sample of every novel class added to that ZSL model by
   ``add_one_shot``, accuracy on the same novel test samples (Table VIII);
6. ``gzsl_seen`` / ``gzsl_unseen`` / ``gzsl_h``: ``recognize`` of the ZSL model (before
   one-shot) on the mixed set of held-out known trials and novel test samples,
   so novelty detection routes each sample: accuracy on the known part, on the
   novel part, and their harmonic mean.

Methods listed in ``ZSL_VARIANTS`` also report extra ZSL figures obtained by
``add_novel_classes`` options (the paper's GEN-F, NEIGHB-F and no-GAN variants,
Tables V-VI). All figures are fractions in [0, 1]; NaN (``null`` in JSON) marks a
figure a method cannot produce.
"""

from __future__ import annotations

import inspect
import math
import platform
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from app.data.dataset import TactileDataset
from app.evaluation import metrics
from app.evaluation.splits import ZslSplit, make_zsl_splits
from app.framework.jsonable import jsonable
from app.framework.recognizer import TactileRecognizer
from app.framework.registry import method_class

FIGURES: tuple[str, ...] = (
    "known_acc",
    "nd_known_kept",
    "nd_val_novel",
    "nd_novel_detected",
    "nd_auroc",
    "zsl",
    "osl",
    "gzsl_seen",
    "gzsl_unseen",
    "gzsl_h",
)

# Extra ZSL figures per method: figure -> add_novel_classes options, or None for
# "the same as ``zsl``" (the method's default enrolment).
ZSL_VARIANTS: dict[str, dict[str, dict[str, Any] | None]] = {
    "paper": {
        "zsl_genf": {"synthesis": "genf"},
        "zsl_neighbf": None,  # the paper pipeline's default enrolment is NEIGHB-F
        "zsl_nogan": {"synthesis": "neighbf", "generator": "alg1"},
    },
}

# Down-sampled length of the novelty tuning curve kept per split for the report.
_CURVE_POINTS = 200


def method_figures(method: str) -> tuple[str, ...]:
    return FIGURES + tuple(ZSL_VARIANTS.get(method, {}))


def make_recognizer(method: str, params: dict[str, Any] | None, seed: int) -> TactileRecognizer:
    """The method's recognizer with ``params``; ``seed`` is passed when the class takes one."""
    cls = method_class(method)
    params = dict(params or {})
    takes_seed = any(
        "seed" in inspect.signature(c.__init__).parameters
        for c in cls.__mro__
        if "__init__" in vars(c)
    )
    if "seed" not in params and takes_seed:
        params["seed"] = seed
    return cls(**params)


def evaluate_split(
    dataset: TactileDataset,
    split: ZslSplit,
    method: str,
    params: dict[str, Any] | None = None,
    seed: int = 0,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """(figures, details) of one method on one split; details hold matrices, curve, timings."""
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    train = split.train_dataset(dataset)
    model = make_recognizer(method, params, seed).fit(train)
    timings["fit_s"] = time.perf_counter() - t0

    xk = dataset.samples[split.known_test_idx]
    yk = split.known_labels(dataset, split.known_test_idx)
    xn = dataset.samples[split.novel_test_idx]
    yn = split.novel_labels(dataset, split.novel_test_idx)
    names = list(split.novel_names)
    n_novel = len(names)
    figures: dict[str, Any] = {
        "split": split.index + 1,
        "novel_objects": list(split.novel_objects),
        "novel_names": names,
    }
    details: dict[str, Any] = {"split": split.index + 1}

    # Known classes and novelty detection (Tables II and III).
    figures["known_acc"] = metrics.argmax_accuracy(model.known_proba(xk), yk)
    tuning = model.novelty_tuning
    figures["nd_known_kept"] = tuning.known_kept_at_threshold if tuning else math.nan
    figures["nd_val_novel"] = tuning.val_novel_at_threshold if tuning else math.nan
    score_known = model.novelty_score(xk)
    score_novel = model.novelty_score(xn)
    figures["nd_novel_detected"] = metrics.detection_rate(score_novel, model.novelty_threshold)
    figures["nd_auroc"] = metrics.novelty_auroc(score_known, score_novel)
    details["novelty_threshold"] = float(model.novelty_threshold)
    details["novelty_tuning"] = _curve(tuning) if tuning else None

    # Zero-shot enrolment (Tables V-VII) and its variants.
    t = time.perf_counter()
    vectors = split.novel_attributes(dataset)
    # a novel object may share its attribute vector with a known object (see splits)
    zsl_model = model.add_novel_classes(names, vectors, allow_known_vectors=True)
    timings["zsl_enrol_s"] = time.perf_counter() - t
    pred = zsl_model.novel_proba(xn).argmax(axis=1)
    figures["zsl"] = metrics.accuracy(yn, pred)
    details["confusion_zsl"] = metrics.confusion_matrix(yn, pred, n_novel).tolist()
    for figure, options in ZSL_VARIANTS.get(method, {}).items():
        if options is None:
            figures[figure] = figures["zsl"]
            details[f"confusion_{figure}"] = details["confusion_zsl"]
            continue
        variant = model.add_novel_classes(names, vectors, allow_known_vectors=True, **options)
        vpred = variant.novel_proba(xn).argmax(axis=1)
        figures[figure] = metrics.accuracy(yn, vpred)
        details[f"confusion_{figure}"] = metrics.confusion_matrix(yn, vpred, n_novel).tolist()

    # One-shot learning (Table VIII): one real sample per novel class.
    t = time.perf_counter()
    osl_model = zsl_model
    for name, i in zip(names, split.one_shot_idx, strict=True):
        osl_model = osl_model.add_one_shot(name, dataset.samples[i : i + 1])
    timings["osl_enrol_s"] = time.perf_counter() - t
    pred = osl_model.novel_proba(xn).argmax(axis=1)
    figures["osl"] = metrics.accuracy(yn, pred)
    details["confusion_osl"] = metrics.confusion_matrix(yn, pred, n_novel).tolist()

    # The full pipeline on known and novel test samples mixed (generalised ZSL).
    known_names = list(train.class_names)
    true = [known_names[j] for j in yk] + [names[j] for j in yn]
    answers = zsl_model.recognize(np.concatenate([xk, xn]), top_k=1)
    is_known = np.r_[np.ones(len(xk), bool), np.zeros(len(xn), bool)]
    figures.update(metrics.gzsl_figures(true, [a.class_name for a in answers], is_known))
    routed_novel = np.array([a.is_novel for a in answers])
    details["gzsl_routed_novel_known"] = float(routed_novel[is_known].mean())
    details["gzsl_routed_novel_novel"] = float(routed_novel[~is_known].mean())

    timings["total_s"] = time.perf_counter() - t0
    details["timings"] = timings
    details["model_metrics"] = jsonable(getattr(model, "metrics", {}) or {})
    return figures, details


def _curve(tuning) -> dict[str, Any]:
    """The tuning curve (Fig. 7), down-sampled to at most _CURVE_POINTS points."""
    n = len(tuning.thresholds)
    keep = np.unique(np.linspace(0, n - 1, min(n, _CURVE_POINTS)).round().astype(int))
    return {
        "thresholds": np.asarray(tuning.thresholds)[keep].tolist(),
        "known_kept": np.asarray(tuning.known_kept)[keep].tolist(),
        "val_novel": np.asarray(tuning.val_novel)[keep].tolist(),
        "threshold": float(tuning.threshold),
        "known_kept_at_threshold": float(tuning.known_kept_at_threshold),
        "val_novel_at_threshold": float(tuning.val_novel_at_threshold),
        "auroc": float(tuning.auroc),
    }


def evaluate(
    dataset: TactileDataset,
    methods: Sequence[str],
    n_novel: int = 6,
    n_splits: int = 7,
    seed: int = 0,
    test_trials: int = 2,
    method_params: dict[str, dict[str, Any]] | None = None,
    progress: bool = True,
    dataset_label: str | None = None,
    distinct_from_known: bool = False,
) -> dict[str, Any]:
    """Every method on the same ``n_splits`` splits; a JSON-ready results dict.

    Layout: {"dataset", "novel", "seed", "splits", "test_trials", "config",
    "split_definitions", "methods": {name: {"splits": [per-split figures],
    "mean": {...}, "std": {...}, "elapsed_s": ..., "details": [per split]}}}.
    """
    methods = list(dict.fromkeys(methods))
    if not methods:
        raise ValueError("no methods to evaluate")
    for m in methods:
        method_class(m)  # fail before any work on an unknown name
    method_params = method_params or {}
    splits = make_zsl_splits(
        dataset,
        n_novel,
        n_splits,
        seed,
        test_trials=test_trials,
        distinct_from_known=distinct_from_known,
    )
    results: dict[str, Any] = {
        "dataset": dataset_label or dataset.name,
        "novel": int(n_novel),
        "seed": int(seed),
        "splits": int(n_splits),
        "test_trials": int(test_trials),
        "config": {
            "distinct_from_known": bool(distinct_from_known),
            "n_objects": dataset.n_classes,
            "n_samples": len(dataset),
            "input_shape": list(dataset.input_shape),
            "attribute_names": list(dataset.attribute_names),
            "method_params": method_params,
            "python": platform.python_version(),
            "machine": platform.machine(),
        },
        "split_definitions": [s.describe(dataset) for s in splits],
        "methods": {m: {"splits": [], "details": [], "elapsed_s": 0.0} for m in methods},
    }
    started = time.perf_counter()
    bar = tqdm(total=len(splits) * len(methods), desc="evaluate", unit="fit", disable=not progress)
    try:
        for split in splits:
            for m in methods:
                bar.set_postfix_str(f"split {split.index + 1}/{len(splits)} {m}")
                t = time.perf_counter()
                figures, details = evaluate_split(dataset, split, m, method_params.get(m), seed)
                entry = results["methods"][m]
                entry["elapsed_s"] += time.perf_counter() - t
                entry["splits"].append(figures)
                entry["details"].append(details)
                bar.update(1)
    finally:
        bar.close()
    for m in methods:
        entry = results["methods"][m]
        entry["mean"], entry["std"] = {}, {}
        for f in method_figures(m):
            mean, std = metrics.summarize([s[f] for s in entry["splits"]])
            entry["mean"][f], entry["std"][f] = mean, std
    results["elapsed_s"] = time.perf_counter() - started
    return jsonable(results)
