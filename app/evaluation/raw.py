"""Known-object recognition from raw BioTac trials (``evaluate --dataset biotac:DIR``).

Two protocols, run for several methods on the same splits; every model is fitted on raw
training trials (``TactileRecognizer.fit`` on a ``BioTacDataset``), so its featurizer's
PCA and normalisation see training trials only, and answers once per test trial from all
of its fingers (``recognize_trials``):

1. Trial-disjoint splits (``trial_splits``): of every object, ``test_trials`` whole trials
   drawn at random are its test data, the rest train; ``n_splits`` such splits from
   ``numpy.random.default_rng(seed)``. Figures per split:

   - ``known_acc``: trials recognised as their object (one answer per trial, both fingers);
   - ``known_acc_finger``: tactile images (one finger each) whose most probable known
     class is their object: what fusing the fingers adds;
   - ``nd_known_kept``: test trials the model calls known (fused novelty score at or
     below its threshold, tuned by Sect. VI-B inside ``fit``).

2. Held-out grip pressure (``pressure_splits``): train on the trials of every set grip
   pressure but one (``BioTacDataset.grip_pressure``), test on that one's trials:
   ``pressure_<P>`` is the trial accuracy on pressure P. The split is fixed by the data,
   so it is fitted ``n_splits`` times with method seeds ``seed``, ``seed + 1``, …: its
   spread is the methods' own randomness, not a choice of trials. ``pressure_mean`` is the
   mean over the held-out pressures of one repeat.

With ``validation=True`` no test trial is used: each trial split's training trials are
split again the same way (``test_trials`` of every object's training trials validate, the
rest train), and for each held-out pressure a model is trained on one of the other
pressures and validated on the remaining one, and the other way round (``pressure_<P>``:
the mean of those validations, the figure that stands for the test on P). That is where
options (``--param``) are chosen, as docs/RESULTS.md reports.

In protocol 1 a method's seed is ``seed + split index``. Summaries per figure: the mean,
the sample standard deviation (ddof 1) and a 95 % confidence interval of the mean from
Student's t over splits (``metrics.mean_interval``, clipped to [0, 1]). Repeated random
splits share trials, so that interval is narrower than the uncertainty about a new set of
trials would be. A held-out pressure's test set is fixed (its trials), so its figures also
get the Wilson 95 % interval of the mean accuracy on that many trials (``binomial95``):
what the size of the test set allows. With several methods, ``paired`` holds each other
method's differences from the first, split by split and repeat by repeat (the same trials
and method seeds), with their mean, t interval and the splits won and lost
(``protocol.paired_summary``). The raw-trial protocol runs in one process.
"""

from __future__ import annotations

import math
import platform
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from app.data.biotac import BioTacDataset
from app.evaluation import metrics, procedures
from app.evaluation.protocol import make_recognizer, paired_summary
from app.evaluation.splits import SplitError
from app.framework.jsonable import jsonable
from app.framework.progress import bar_disabled
from app.framework.registry import method_class

TRIAL_FIGURES = ("known_acc", "known_acc_finger", "nd_known_kept")
PROTOCOL = "raw-trials"


def pressure_figure(pressure: float) -> str:
    """``pressure_100`` for 100 (a whole number), ``pressure_12.5`` otherwise."""
    return f"pressure_{pressure:g}"


def trial_splits(
    raw: BioTacDataset, n_splits: int, seed: int, test_trials: int = 3
) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n_splits`` (train, test) trial-index pairs: of every object, ``test_trials`` of its
    trials drawn at random are test data and the rest train (SplitError if an object has
    too few)."""
    if not isinstance(n_splits, int | np.integer) or n_splits < 1:
        raise SplitError(f"n_splits must be a positive integer, got {n_splits!r}")
    if not isinstance(test_trials, int | np.integer) or test_trials < 1:
        raise SplitError(f"test_trials must be a positive integer, got {test_trials!r}")
    by_class = [np.flatnonzero(raw.labels == c) for c in range(raw.n_classes)]
    for c, rows in enumerate(by_class):
        if len(rows) <= test_trials:
            raise SplitError(
                f"object '{raw.class_names[c]}' has {len(rows)} trial(s); holding out "
                f"{test_trials} would leave none to train on"
            )
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n_splits):
        test = np.sort(
            np.concatenate([rng.choice(rows, size=test_trials, replace=False) for rows in by_class])
        )
        out.append((np.setdiff1d(np.arange(len(raw)), test), test))
    return out


def validation_split(
    raw: BioTacDataset, train: np.ndarray, test_trials: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """(fit, validation) trial indices carved from ``train``: ``test_trials`` of every
    object's training trials validate, the rest fit."""
    val = []
    for c in range(raw.n_classes):
        rows = train[raw.labels[train] == c]
        if len(rows) <= test_trials:
            raise SplitError(
                f"object '{raw.class_names[c]}' has {len(rows)} training trial(s); validating "
                f"on {test_trials} would leave none to fit on"
            )
        val.append(rng.choice(rows, size=test_trials, replace=False))
    held = np.sort(np.concatenate(val))
    return np.setdiff1d(train, held), held


def pressure_validation_splits(
    raw: BioTacDataset,
) -> dict[float, list[tuple[np.ndarray, np.ndarray]]]:
    """Held-out pressure P -> the (fit, validation) pairs that stand for its test without
    touching it: fit on one other pressure, validate on another, every ordered pair."""
    folds = pressure_splits(raw)
    pressure = raw.grip_pressure
    out: dict[float, list[tuple[np.ndarray, np.ndarray]]] = {}
    for level in folds:
        others = [q for q in folds if q != level]
        if len(others) < 2:
            raise SplitError(
                "validating a held-out pressure needs two other pressures (fit on one, "
                f"validate on the other), got {len(others)}"
            )
        pairs = []
        for fit_level in others:
            for val_level in others:
                if fit_level != val_level:
                    pairs.append(
                        (
                            np.flatnonzero(pressure == fit_level),
                            np.flatnonzero(pressure == val_level),
                        )
                    )
        out[level] = pairs
    return out


def pressure_splits(raw: BioTacDataset) -> dict[float, tuple[np.ndarray, np.ndarray]]:
    """Set grip pressure -> (train, test) trial indices: test on the trials of that
    pressure, train on those of the others. SplitError when fewer than 2 pressures are
    known, a trial has none, or holding one out leaves an object without training trials."""
    pressure = raw.grip_pressure
    if np.isnan(pressure).any():
        i = int(np.flatnonzero(np.isnan(pressure))[0])
        raise SplitError(
            f"trial {raw.groups[i]!r} has no grip pressure in its name (…_pdc<P>_…); the "
            "held-out pressure protocol needs one for every trial"
        )
    levels = np.unique(pressure)
    if len(levels) < 2:
        raise SplitError(f"held-out pressure needs 2 or more grip pressures, got {levels.tolist()}")
    out = {}
    for level in levels.tolist():
        test = np.flatnonzero(pressure == level)
        train = np.flatnonzero(pressure != level)
        missing = sorted(set(range(raw.n_classes)) - set(raw.labels[train].tolist()))
        if missing:
            raise SplitError(
                f"holding out grip pressure {level:g} leaves object "
                f"'{raw.class_names[missing[0]]}' without training trials"
            )
        out[float(level)] = (train, test)
    return out


def _fit(raw: BioTacDataset, train: np.ndarray, method: str, params: dict | None, seed: int):
    return make_recognizer(method, params, seed).fit(raw.subset(train))


def evaluate_trial_split(
    raw: BioTacDataset,
    train: np.ndarray,
    test: np.ndarray,
    method: str,
    params: dict[str, Any] | None,
    seed: int,
    durations: Mapping[str, float] | None = None,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """(figures, details) of one method on one trial-disjoint split; with ``durations``
    (seconds by procedure name, ``procedures.check_durations``), also the figures against
    the phases used (``procedures.measure_known``) where the model answers from some."""
    t0 = time.perf_counter()
    model = _fit(raw, train, method, params, seed)
    fit_s = time.perf_counter() - t0
    trials = list(raw.subset(test).trials)
    truth = raw.labels[test]
    images, index = model.trial_samples(trials)
    answers = model.recognize_batch(images, top_k=1, groups=index)
    pred = answers.top_index[:, 0]
    finger_pred = model.known_proba(images).argmax(axis=1)
    figures = {
        "known_acc": metrics.accuracy(truth, pred),
        "known_acc_finger": metrics.accuracy(truth[index], finger_pred),
        "nd_known_kept": float(np.mean(~answers.is_novel)),
    }
    if durations is not None and model.answers_from_some_procedures:
        seconds = procedures.check_durations(model.procedures, durations)
        figures.update(procedures.measure_known(model, images, truth, index, seconds))
    details = {
        "test_trials": [raw.groups[i] for i in test],
        "confusion": metrics.confusion_matrix(truth, pred, raw.n_classes).tolist(),
        "novelty_threshold": float(model.novelty_threshold),
        "timings": {"fit_s": fit_s, "total_s": time.perf_counter() - t0},
        "model_metrics": jsonable(getattr(model, "metrics", {}) or {}),
        "procedures": list(model.procedures),
    }
    return figures, details


def evaluate_pressure(
    raw: BioTacDataset,
    train: np.ndarray,
    test: np.ndarray,
    method: str,
    params: dict[str, Any] | None,
    seed: int,
) -> tuple[float, list[list[int]], float]:
    """(trial accuracy, confusion matrix, fit seconds) of one held-out-pressure fit."""
    t0 = time.perf_counter()
    model = _fit(raw, train, method, params, seed)
    fit_s = time.perf_counter() - t0
    pred = model.recognize_trials(list(raw.subset(test).trials), top_k=1).top_index[:, 0]
    truth = raw.labels[test]
    cm = metrics.confusion_matrix(truth, pred, raw.n_classes).tolist()
    return metrics.accuracy(truth, pred), cm, fit_s


def _summary(
    values: Sequence[float], bounds: tuple[float, float] | None = (0.0, 1.0)
) -> tuple[float, float, list[float]]:
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan"), float("nan"), [float("nan"), float("nan")]
    std = float(v.std(ddof=1)) if v.size > 1 else float("nan")
    return float(v.mean()), std, list(metrics.mean_interval(v, bounds=bounds))


def evaluate_raw(
    raw: BioTacDataset,
    methods: Sequence[str],
    n_splits: int = 10,
    seed: int = 0,
    test_trials: int = 3,
    method_params: dict[str, dict[str, Any]] | None = None,
    progress: bool = True,
    dataset_label: str | None = None,
    held_out_pressure: bool = True,
    validation: bool = False,
    procedures_measured: bool = False,
    durations: Mapping[str, float] | None = None,
) -> dict[str, Any]:
    """Both protocols (see the module docstring) for every method; a JSON-ready dict.
    ``validation``: measure on validation trials carved from the training trials only.
    ``procedures_measured``: on the trial splits, also the figures against the phases used
    (``procedures.measure_known``; each phase's seconds from ``durations``, else
    ``procedures.DURATIONS``), with ``procedures``, ``durations`` and
    ``procedure_targets`` in the results.

    Layout: {"dataset", "protocol": "raw-trials", "seed", "splits", "test_trials",
    "pressures", "config", "split_definitions", "methods": {name: {"splits": [per-split
    figures], "pressure": [{"pressure", "repeat", "seed", "accuracy"}], "mean", "std",
    "ci95" ([low, high] per figure), "binomial95" ([low, high] per held-out pressure),
    "confusion" (trial splits, summed), "confusion_pressure" (summed), "elapsed_s",
    "details"}}, "paired": each other method's differences from the first, split by split
    and repeat by repeat (mean, 95 % t interval, won / lost; only with several methods)}.
    """
    methods = list(dict.fromkeys(methods))
    if not methods:
        raise ValueError("no methods to evaluate")
    for m in methods:
        method_class(m)  # fail before any work on an unknown name
    method_params = method_params or {}
    splits = trial_splits(raw, n_splits, seed, test_trials)
    by_pressure: dict[float, list[tuple[np.ndarray, np.ndarray]]] = {}
    if held_out_pressure:
        by_pressure = (
            pressure_validation_splits(raw)
            if validation
            else {level: [pair] for level, pair in pressure_splits(raw).items()}
        )
    if validation:
        rng = np.random.default_rng([seed, 1])
        splits = [validation_split(raw, train, test_trials, rng) for train, _ in splits]
    results: dict[str, Any] = {
        "dataset": dataset_label or raw.name,
        "protocol": PROTOCOL,
        "validation": bool(validation),
        "seed": int(seed),
        "splits": int(n_splits),
        "test_trials": int(test_trials),
        "pressures": sorted(by_pressure),
        "config": {
            "class_names": list(raw.class_names),
            "n_objects": raw.n_classes,
            "n_trials": len(raw),
            "fingers_per_trial": sorted({t.n_fingers for t in raw.trials}),
            "n_attributes": len(raw.attribute_names),
            "method_params": method_params,
            "python": platform.python_version(),
            "machine": platform.machine(),
        },
        "split_definitions": [
            {"index": i, "test_trials": [raw.groups[j] for j in test]}
            for i, (_, test) in enumerate(splits)
        ],
        "methods": {},
    }
    seconds = None
    if procedures_measured:
        seconds = {**procedures.DURATIONS, **(durations or {})}
        results["procedures_measured"] = True
        results["procedure_targets"] = list(procedures.TARGETS)
    k = raw.n_classes
    total = len(methods) * (len(splits) + n_splits * sum(map(len, by_pressure.values())))
    bar = tqdm(total=total, desc="evaluate", unit="fit", disable=bar_disabled(progress))
    started = time.perf_counter()
    try:
        for m in methods:
            t_method = time.perf_counter()
            params = method_params.get(m)
            entry: dict[str, Any] = {"splits": [], "pressure": [], "details": []}
            confusion = np.zeros((k, k), np.int64)
            for i, (train, test) in enumerate(splits):
                bar.set_postfix_str(f"{m} split {i + 1}/{len(splits)}")
                figures, details = evaluate_trial_split(
                    raw, train, test, m, params, seed + i, seconds
                )
                if seconds is not None and details["procedures"] and "procedures" not in results:
                    names = details["procedures"]
                    results["procedures"] = names
                    results["durations"] = procedures.check_durations(names, seconds).tolist()
                entry["splits"].append({"split": i + 1, **figures})
                entry["details"].append({"split": i + 1, **details})
                confusion += np.asarray(details["confusion"])
                bar.update(1)
            confusion_pressure = np.zeros((k, k), np.int64)
            for level, pairs in by_pressure.items():
                for r in range(n_splits):
                    bar.set_postfix_str(f"{m} pressure {level:g} repeat {r + 1}/{n_splits}")
                    accs, n_test, fit_s = [], 0, 0.0
                    for train, test in pairs:
                        acc, cm, s = evaluate_pressure(raw, train, test, m, params, seed + r)
                        accs.append(acc)
                        n_test += len(test)
                        fit_s += s
                        confusion_pressure += np.asarray(cm)
                        bar.update(1)
                    entry["pressure"].append(
                        {
                            "pressure": level,
                            "repeat": r + 1,
                            "seed": seed + r,
                            "accuracy": float(np.mean(accs)),
                            "n_test_trials": int(n_test),
                            "fit_s": fit_s / len(pairs),
                        }
                    )
            entry["confusion"] = confusion.tolist()
            entry["confusion_pressure"] = confusion_pressure.tolist()
            _summarise(entry, list(by_pressure), n_splits)
            entry["elapsed_s"] = time.perf_counter() - t_method
            results["methods"][m] = entry
    finally:
        bar.close()
    if len(methods) > 1:
        results["paired"] = _paired(results["methods"], list(by_pressure), n_splits)
    results["elapsed_s"] = time.perf_counter() - started
    return jsonable(results)


def _series(entry: dict[str, Any], pressures: list[float], n_repeats: int) -> dict[str, list]:
    """Every figure's values in split (repeat) order: split i and repeat i share seed + i."""
    present = [f for f in entry["splits"][0] if f != "split"] if entry["splits"] else []
    series: dict[str, list[float]] = {f: [s[f] for s in entry["splits"]] for f in present}
    for level in pressures:
        series[pressure_figure(level)] = [
            p["accuracy"] for p in entry["pressure"] if p["pressure"] == level
        ]
    if pressures:
        series["pressure_mean"] = [
            float(np.mean([series[pressure_figure(level)][r] for level in pressures]))
            for r in range(n_repeats)
        ]
    return series


def _paired(entries: dict[str, dict[str, Any]], pressures: list[float], n_repeats: int):
    """Every method against the first on the same trial splits and held-out-pressure repeats
    (see ``protocol.paired_summary``)."""
    rows = {}
    for m, entry in entries.items():
        series = _series(entry, pressures, n_repeats)
        n = max(map(len, series.values()))
        rows[m] = {
            "splits": [
                {"split": i + 1, **{f: v[i] for f, v in series.items() if i < len(v)}}
                for i in range(n)
            ],
            "mean": entry["mean"],
        }
    return paired_summary(rows, next(iter(entries)))


def _summarise(entry: dict[str, Any], pressures: list[float], n_repeats: int) -> None:
    series = _series(entry, pressures, n_repeats)
    entry["mean"], entry["std"], entry["ci95"] = {}, {}, {}
    for figure, values in series.items():
        # shares in [0, 1], but the adaptive rule's count of procedures
        bounds = None if figure.endswith("_procedures") else (0.0, 1.0)
        summary = _summary(values, bounds)
        entry["mean"][figure], entry["std"][figure], entry["ci95"][figure] = summary
    entry["binomial95"] = {}
    for level in pressures:
        figure = pressure_figure(level)
        n = next(p["n_test_trials"] for p in entry["pressure"] if p["pressure"] == level)
        entry["binomial95"][figure] = list(metrics.wilson_interval(entry["mean"][figure], n))


def raw_figures(results: dict[str, Any]) -> list[str]:
    """The measured figures of raw-trial results (a finite mean for some method), in report
    order; those against the phases used (``procs…``, ``adaptive…``) have a section of their
    own."""
    present: list[str] = []
    for entry in results["methods"].values():
        present += [
            f
            for f, v in entry.get("mean", {}).items()
            if f not in present
            and not f.startswith(("procs", "adaptive"))
            and v is not None
            and math.isfinite(v)
        ]
    order = [*TRIAL_FIGURES, *(pressure_figure(p) for p in results.get("pressures", []))]
    order.append("pressure_mean")
    return [f for f in order if f in present] + [f for f in present if f not in order]
