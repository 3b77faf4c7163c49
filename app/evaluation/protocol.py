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

With ``ceilings=True`` every method also reports measured limits on the same split
(``CEILING_FIGURES``): novelty detection at the best threshold for its score, chosen on
the test samples themselves (``metrics.oracle_threshold``), beside its tuned threshold
measured the same way (``nd_test_kept``, ``nd_balance``); and the mixed known + novel
figures under perfect routing (every known test trial to the known-class classifier,
every novel test sample to the zero-shot classifier), so ``ceil_gzsl_seen`` is
``known_acc``, ``ceil_gzsl_unseen`` is ``zsl`` and ``ceil_gzsl_h`` their harmonic mean.
Routing can only lose answers, so ``ceil_gzsl_*`` ≥ ``gzsl_*`` and ``ceil_nd_balance`` ≥
``nd_balance`` on every split.

Summaries over splits (``summarize_entry``): the mean, the standard deviation (ddof 0, the
``std`` key kept from the first layout) and ``ci95``, the 95 % confidence interval of the
mean from Student's t with n - 1 degrees of freedom and the sample standard deviation
(``metrics.mean_interval``), clipped to [0, 1], and ``rerun95``, where the mean of a re-run
of the same command on another seed with ``rerun_splits`` splits lands, 95 %
(``metrics.rerun_interval``: a confidence interval holds the true mean, and catches a
re-run's mean less often, since that moves too). With several methods, ``paired`` holds each
method's per-split difference from the first method (the reference) on the same splits,
its mean, its t interval (clipped to [-1, 1]) and the splits won and lost. Repeated
random splits share objects and trials, so these intervals are narrower than the
uncertainty about new objects would be; they say whether a difference is larger than the
split-to-split noise.

Splits are independent: each draws its objects and trials from ``seed`` and gives its
methods a seed of its own (``split_method_seed``), so the intervals over splits count the
methods' randomness too. ``jobs`` > 1 runs them in that many worker processes, each split's
methods in order with the same seeds as in one process, so the figures are the same.
"""

from __future__ import annotations

import inspect
import math
import multiprocessing
import platform
import sys
import time
from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from app.data.dataset import TactileDataset
from app.evaluation import metrics
from app.evaluation.procedures import TARGETS, check_durations, procedure_figures
from app.evaluation.procedures import measure as measure_procedures
from app.evaluation.splits import ZslSplit, make_zsl_splits
from app.evaluation.tables import TABLE_FIGURES, TABLES_STREAM
from app.evaluation.tables import measure as measure_tables
from app.evaluation.touches import check_touches, touch_figures
from app.evaluation.touches import measure as measure_touches
from app.framework.jsonable import jsonable
from app.framework.progress import bar_disabled
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

# Measured limits on the same split (``evaluate(..., ceilings=True)``).
CEILING_FIGURES: tuple[str, ...] = (
    "nd_test_kept",  # held-out known test trials called known at the tuned threshold
    "nd_balance",  # min(nd_test_kept, nd_novel_detected)
    "ceil_nd_test_kept",  # the same two at the oracle threshold (chosen on the test samples)
    "ceil_nd_novel_detected",
    "ceil_nd_balance",  # max over thresholds of min(known test kept, novel detected)
    "ceil_gzsl_seen",  # perfect routing: = known_acc
    "ceil_gzsl_unseen",  # perfect routing: = zsl
    "ceil_gzsl_h",
)
INTERVALS = (
    "95% confidence interval of the mean over splits: Student's t with n - 1 degrees of "
    "freedom and the sample standard deviation, clipped to [0, 1]; paired differences: the "
    "same over the per-split differences from the reference method on the same splits, "
    "clipped to [-1, 1]. Splits share objects and trials, so the intervals understate the "
    "uncertainty about new objects. A confidence interval holds the true mean, not the mean "
    "of a re-run on another seed (both means move); rerun95 is where that re-run's mean "
    "lands, 95%: a bootstrap prediction interval over the splits' values."
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


def method_figures(
    method: str,
    ceilings: bool = False,
    touches: Sequence[int] = (),
    n_procedures: int = 0,
    tables: bool = False,
) -> tuple[str, ...]:
    extra = CEILING_FIGURES if ceilings else ()
    return (
        FIGURES
        + tuple(ZSL_VARIANTS.get(method, {}))
        + extra
        + touch_figures(touches)
        + procedure_figures(n_procedures)
        + (TABLE_FIGURES if tables else ())
    )


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
    ceilings: bool = False,
    touches: Sequence[int] = (),
    durations: np.ndarray | None = None,
    tables: bool = False,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """(figures, details) of one method on one split; details hold matrices, curve, timings.
    ``ceilings``: also the measured limits of ``CEILING_FIGURES``; ``touches``: also the
    figures after that many touches of each test object, and after one enrolled touch
    (``app.evaluation.touches``); ``durations`` (seconds per procedure): also the figures
    against the procedures used (``app.evaluation.procedures``); ``tables``: also the figures
    of tables of objects named jointly (``app.evaluation.tables``)."""
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
    # the model's guess on every test sample, input outliers too: the research figures
    # measure the classifier, not the service's abstention
    answers = zsl_model.recognize(np.concatenate([xk, xn]), top_k=1, outliers="answer")
    is_known = np.r_[np.ones(len(xk), bool), np.zeros(len(xn), bool)]
    figures.update(metrics.gzsl_figures(true, [a.class_name for a in answers], is_known))
    routed_novel = np.array([a.is_novel for a in answers])
    details["gzsl_routed_novel_known"] = float(routed_novel[is_known].mean())
    details["gzsl_routed_novel_novel"] = float(routed_novel[~is_known].mean())

    if ceilings:
        kept = float(np.mean(score_known <= model.novelty_threshold))
        figures["nd_test_kept"] = kept
        figures["nd_balance"] = min(kept, figures["nd_novel_detected"])
        threshold, oracle_kept, oracle_detected = metrics.oracle_threshold(score_known, score_novel)
        figures["ceil_nd_test_kept"] = oracle_kept
        figures["ceil_nd_novel_detected"] = oracle_detected
        figures["ceil_nd_balance"] = min(oracle_kept, oracle_detected)
        details["oracle_threshold"] = threshold
        # perfect routing: known test trials answered by the known-class classifier (as in
        # known_acc), novel test samples by the zero-shot one (as in zsl)
        figures["ceil_gzsl_seen"] = figures["known_acc"]
        figures["ceil_gzsl_unseen"] = figures["zsl"]
        figures["ceil_gzsl_h"] = metrics.harmonic_mean(figures["known_acc"], figures["zsl"])

    if touches:
        t = time.perf_counter()
        figures.update(
            measure_touches(
                zsl_model,
                osl_model,
                (xk, yk, dataset.trials[split.known_test_idx]),
                (xn, yn, dataset.trials[split.novel_test_idx]),
                known_names,
                names,
                touches,
                np.random.default_rng([seed, split.index]),
            )
        )
        timings["touches_s"] = time.perf_counter() - t

    if durations is not None:
        t = time.perf_counter()
        figures.update(
            measure_procedures(
                zsl_model, (xk, yk), (xn, yn), known_names, names, np.asarray(durations)
            )
        )
        timings["procedures_s"] = time.perf_counter() - t

    if tables:
        t = time.perf_counter()
        figures.update(
            measure_tables(
                zsl_model,
                (xk, yk, dataset.trials[split.known_test_idx]),
                (xn, yn, dataset.trials[split.novel_test_idx]),
                known_names,
                names,
                np.random.default_rng([seed, split.index, TABLES_STREAM]),
            )
        )
        timings["tables_s"] = time.perf_counter() - t

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
    jobs: int = 1,
    ceilings: bool = False,
    touches: Sequence[int] = (),
    rerun_splits: int | None = None,
    procedures: bool = False,
    durations: Mapping[str, float] | None = None,
    tables: bool = False,
) -> dict[str, Any]:
    """Every method on the same ``n_splits`` splits; a JSON-ready results dict.

    Layout: {"dataset", "novel", "seed", "splits", "test_trials", "config", "jobs",
    "ceilings", "intervals", "split_definitions", "methods": {name: {"splits": [per-split
    figures], "mean": {...}, "std": {...}, "ci95": {figure: [low, high]}, "rerun95": {...},
    "elapsed_s": ..., "details": [per split]}}, "rerun_splits", "paired": {"reference":
    first method, "methods": {other:
    {"mean", "ci95", "won", "lost", "splits"}}}}; ``paired`` only with several methods.

    ``jobs``: worker processes running splits side by side (1: this process). Each split
    runs every method in order with that split's own method seed (``split_method_seed``,
    in its details as ``method_seed``; a ``seed`` in ``method_params`` overrides it for every
    split), whichever process runs it, so the figures do not depend on ``jobs``;
    ``progress`` prints a line per finished split to stderr below the bar. ``ceilings``:
    also the figures of ``CEILING_FIGURES``.
    ``touches``: touch counts (at most ``test_trials``) for ``app.evaluation.touches``'s
    figures; ValueError naming the problem otherwise. ``rerun_splits``: the size of the
    re-run that ``rerun95`` predicts (default ``n_splits``). ``procedures``: also the
    figures against the procedures used (``app.evaluation.procedures``), with each
    procedure's seconds from ``durations`` (else ``procedures.DURATIONS``). ``tables``: also
    the figures of tables of objects named jointly (``app.evaluation.tables``).
    """
    touches = check_touches(touches, test_trials)
    seconds = None
    if procedures:
        if len(dataset.procedures) < 2:
            raise ValueError(
                f"dataset '{dataset.name}' names {len(dataset.procedures)} procedures; the "
                "figures against the procedures used need at least 2"
            )
        seconds = check_durations(dataset.procedures, durations or {})
    if rerun_splits is not None and (
        not isinstance(rerun_splits, int | np.integer) or rerun_splits < 1
    ):
        raise ValueError(f"rerun_splits must be a positive integer, got {rerun_splits!r}")
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
    if not isinstance(jobs, int | np.integer) or jobs < 1:
        raise ValueError(f"jobs must be a positive integer, got {jobs!r}")
    jobs = min(int(jobs), len(splits))
    results["jobs"] = jobs
    results["ceilings"] = bool(ceilings)
    results["touches"] = touches
    results["procedures_measured"] = seconds is not None
    results["procedures"] = list(dataset.procedures)
    results["tables"] = bool(tables)
    if seconds is not None:
        results["durations"] = seconds.tolist()
        results["procedure_targets"] = list(TARGETS)
    results["intervals"] = INTERVALS
    results["rerun_splits"] = int(rerun_splits or n_splits)
    started = time.perf_counter()
    bar = tqdm(
        total=len(splits) * len(methods),
        desc="evaluate",
        unit="fit",
        disable=bar_disabled(progress),
    )
    per_split: dict[int, list[tuple[dict, dict, float]]] = {}

    def finished(index: int, outcome: list[tuple[dict, dict, float]]) -> None:
        per_split[index] = outcome
        if progress:
            heads = ", ".join(
                f"{m} gzsl_h {f['gzsl_h']:.3f}"
                for m, (f, _, _) in zip(methods, outcome, strict=True)
            )
            seconds = sum(t for _, _, t in outcome)
            bar.write(
                f"split {index + 1}/{len(splits)} done ({len(per_split)} of {len(splits)}, "
                f"{seconds:.0f} s): {heads}",
                file=sys.stderr,
            )

    try:
        if jobs == 1:
            for split in splits:
                outcome = []
                for m in methods:
                    bar.set_postfix_str(f"split {split.index + 1}/{len(splits)} {m}")
                    outcome.append(
                        _run_method(
                            dataset,
                            split,
                            m,
                            method_params.get(m),
                            seed,
                            ceilings,
                            touches,
                            seconds,
                            tables,
                        )
                    )
                    bar.update(1)
                finished(split.index, outcome)
        else:
            # spawn: a fresh interpreter per worker (no forked torch or BLAS thread state)
            pool = ProcessPoolExecutor(
                max_workers=jobs,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_init_worker,
                initargs=(dataset,),
            )
            try:
                bar.set_postfix_str(f"{jobs} processes")
                futures = {
                    pool.submit(
                        _split_task,
                        split,
                        methods,
                        method_params,
                        seed,
                        ceilings,
                        touches,
                        seconds,
                        tables,
                    ): split
                    for split in splits
                }
                for future in as_completed(futures):
                    finished(futures[future].index, future.result())
                    bar.update(len(methods))
            except BaseException:
                # a failed split or Ctrl-C: drop the splits not started, do not wait for them
                pool.shutdown(wait=False, cancel_futures=True)
                raise
            pool.shutdown()
    finally:
        bar.close()
    for split in splits:
        for m, (figures, details, elapsed) in zip(methods, per_split[split.index], strict=True):
            entry = results["methods"][m]
            entry["elapsed_s"] += elapsed
            entry["splits"].append(figures)
            entry["details"].append(details)
    # the figures against the procedures only when they were measured (``seconds``)
    n_procedures = len(dataset.procedures) if seconds is not None else 0
    for m in methods:
        summarize_entry(
            results["methods"][m],
            method_figures(m, ceilings, touches, n_procedures, tables),
            results["rerun_splits"],
        )
    if len(methods) > 1:
        results["paired"] = paired_summary(results["methods"], methods[0])
    results["elapsed_s"] = time.perf_counter() - started
    return jsonable(results)


def _run_method(
    dataset: TactileDataset,
    split: ZslSplit,
    method: str,
    params: dict[str, Any] | None,
    seed: int,
    ceilings: bool,
    touches: Sequence[int] = (),
    durations: np.ndarray | None = None,
    tables: bool = False,
) -> tuple[dict[str, Any], dict[str, Any], float]:
    t = time.perf_counter()
    own_seed = split_method_seed(seed, split.index)
    figures, details = evaluate_split(
        dataset, split, method, params, own_seed, ceilings, touches, durations, tables
    )
    details["method_seed"] = own_seed
    return figures, details, time.perf_counter() - t


def split_method_seed(seed: int, index: int) -> int:
    """The method seed of split ``index`` of a run with seed ``seed``: its own for every split
    (numpy's SeedSequence of the pair, below 2**31 so that ``seed + r`` stays a valid
    scikit-learn seed). One seed shared by every split would be a random effect that no
    number of splits averages out: it picks the same validation objects for the novelty
    threshold in most splits, and before 2026-11-24 it moved `best`'s 50-split novelty
    detection by ~0.02 from one seed to the next, several times its interval's half-width."""
    return int(np.random.SeedSequence([int(seed), int(index)]).generate_state(1)[0] >> 1)


_WORKER_DATASET: TactileDataset | None = None


def _init_worker(dataset: TactileDataset) -> None:
    """A worker process's start: the dataset once, and the threads the CLI would choose
    (``configure_threads``: TACTILE_TORCH_THREADS, else one, as in the parent)."""
    global _WORKER_DATASET
    from app.framework.runtime import configure_threads

    configure_threads()
    _WORKER_DATASET = dataset


def _split_task(
    split: ZslSplit,
    methods: list[str],
    method_params: dict[str, dict[str, Any]],
    seed: int,
    ceilings: bool,
    touches: Sequence[int] = (),
    durations: np.ndarray | None = None,
    tables: bool = False,
) -> list[tuple[dict[str, Any], dict[str, Any], float]]:
    """Every method on one split, in order (a worker process's task)."""
    assert _WORKER_DATASET is not None, "worker not initialised"
    return [
        _run_method(
            _WORKER_DATASET,
            split,
            m,
            method_params.get(m),
            seed,
            ceilings,
            touches,
            durations,
            tables,
        )
        for m in methods
    ]


def summarize_entry(
    entry: dict[str, Any], figures: Sequence[str], rerun_splits: int | None = None
) -> None:
    """A method's ``mean``, ``std`` (ddof 0), ``ci95`` ([low, high], Student's t over
    splits, clipped to [0, 1] but for counts of procedures) and ``rerun95`` (where the mean
    of a re-run over ``rerun_splits`` splits, default as many, lands:
    ``metrics.rerun_interval``) of every figure, from its ``splits``."""
    entry["mean"], entry["std"], entry["ci95"], entry["rerun95"] = {}, {}, {}, {}
    for f in figures:
        values = [s.get(f, math.nan) for s in entry["splits"]]
        # every figure is a share in [0, 1] but the adaptive rule's count of procedures
        bounds = None if f.endswith("_procedures") else (0.0, 1.0)
        entry["mean"][f], entry["std"][f] = metrics.summarize(values)
        entry["ci95"][f] = list(metrics.mean_interval(values, bounds=bounds))
        entry["rerun95"][f] = list(metrics.rerun_interval(values, rerun_splits, bounds=bounds))


def paired_summary(entries: dict[str, dict[str, Any]], reference: str) -> dict[str, Any]:
    """Every method against ``reference`` on the same splits: per figure both report, the
    per-split differences (method - reference), their mean, their 95 % t interval (clipped
    to [-1, 1]) and the splits on which the method is above (won) or below (lost) it."""
    ref = entries[reference]
    out: dict[str, Any] = {"reference": reference, "methods": {}}
    for m, entry in entries.items():
        if m == reference:
            continue
        out["methods"][m] = paired_entry(entry, ref)
    return out


def paired_entry(entry: dict[str, Any], reference: dict[str, Any]) -> dict[str, Any]:
    """One method's paired differences from ``reference`` (see ``paired_summary``)."""
    if len(entry["splits"]) != len(reference["splits"]):
        raise ValueError("paired differences need the same splits for both methods")
    for a, b in zip(entry["splits"], reference["splits"], strict=True):
        if a.get("split") != b.get("split"):
            raise ValueError("paired differences need the same splits in the same order")
    figures = [f for f in reference.get("mean", {}) if f in entry.get("mean", {})]
    out: dict[str, Any] = {"mean": {}, "ci95": {}, "won": {}, "lost": {}, "splits": {}}
    for f in figures:
        d = metrics.paired_differences(
            [s.get(f, math.nan) for s in entry["splits"]],
            [s.get(f, math.nan) for s in reference["splits"]],
        )
        arr = np.asarray(d)
        out["splits"][f] = d
        out["mean"][f] = metrics.summarize(d)[0]
        out["ci95"][f] = list(metrics.mean_interval(d, bounds=(-1.0, 1.0)))
        out["won"][f] = int(np.sum(arr > 0))
        out["lost"][f] = int(np.sum(arr < 0))
    return out
