"""``tactile-zsl evaluate``: the paper's Sect. VI protocol on random known/novel splits, or,
for raw BioTac trials (``biotac:DIR``), known-object recognition on trial-disjoint splits and
held-out grip pressures (``app.evaluation.raw``)."""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path


def _methods(value: str) -> list[str]:
    names = [m.strip() for m in value.split(",") if m.strip()]
    if not names:
        raise argparse.ArgumentTypeError("give at least one method name")
    return names


def _positive(value: str) -> int:
    try:
        n = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {n}")
    return n


def default_jobs() -> int:
    """The cores this process may run on (its CPU affinity), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # no sched_getaffinity on this platform
        return max(1, os.cpu_count() or 1)


def _touch_counts(value: str) -> list[int]:
    return [_positive(v.strip()) for v in value.split(",") if v.strip()]


def _durations(value: str) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in value.split(","):
        name, sep, seconds = item.partition("=")
        try:
            out[name.strip()] = float(seconds)
        except ValueError:
            sep = ""
        if not sep or not name.strip() or not out[name.strip()] > 0:
            raise argparse.ArgumentTypeError(
                f"expected NAME=SECONDS with SECONDS > 0, got {item!r}"
            )
    return out


def register(subparsers: argparse._SubParsersAction) -> None:
    from app.framework.registry import DEFAULT_METHOD, METHODS

    p = subparsers.add_parser(
        "evaluate",
        help="measure methods on random known/novel object splits (the paper's Sect. VI)",
        description=(
            "Draw --splits random splits of the dataset's objects into known and --novel novel "
            "objects (novel attribute vectors pairwise distinct and covered by the known set; "
            "test data held out by whole trials), fit every method on each split's known "
            "training trials and measure: known-class accuracy, novelty detection (tuned by "
            "Sect. VI-B on validation objects carved from the known set), AUROC, zero-shot and "
            "one-shot accuracy on the novel objects, and the full pipeline on known and novel "
            "test trials mixed (gzsl_seen, gzsl_unseen, gzsl_h). Writes the figures per split "
            "and their means as JSON, each mean with its 95% confidence interval over splits "
            "(Student's t over the per-split values, clipped to [0, 1]); with several "
            "--methods, also each method's paired difference from the first one on the same "
            "splits, with its 95% t interval and the splits won and lost. --ceilings adds "
            "measured limits on the same splits: novelty detection at the threshold chosen "
            "on the test samples themselves, and gzsl_h under perfect routing. Splits run in "
            "--jobs processes side by side, with the same figures as in one. A 'biotac:DIR' "
            "dataset of raw BioTac trials is measured "
            "by the raw-trial protocol instead: known-object accuracy over --splits "
            "trial-disjoint splits (--test-trials whole trials per object held out), each "
            "model fitted on raw training trials (its tactile-image featurizer too) and "
            "answering once per trial from both fingers, and accuracy on each held-out grip "
            "pressure (train on the others), each with its standard deviation and 95% "
            "confidence interval, and the paired differences from the first method; --novel "
            "and --ceilings do not apply, and it runs in one process."
        ),
    )
    p.add_argument(
        "--dataset",
        default="simulated",
        help="dataset spec: 'phac2:PATH' (PHAC-2 static features folder), 'simulated' or "
        "'simulated:N' (built-in simulator with N objects), 'folder:DIR', or 'biotac:DIR' "
        "(raw BioTac trials: the raw-trial protocol); default: %(default)s",
    )
    p.add_argument(
        "--novel",
        type=_positive,
        default=6,
        help="number of novel (zero-shot) objects per split; the paper uses 6 and 12 "
        "(default: %(default)s)",
    )
    p.add_argument(
        "--splits",
        type=_positive,
        default=None,
        help="number of random known/novel splits; the paper uses 7 (default: 7; for raw "
        "trials: 10 trial-disjoint splits, and 10 fits per held-out grip pressure)",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of the split draws and of the methods' own randomness: each split derives "
        "a method seed of its own from it (default: %(default)s)",
    )
    p.add_argument(
        "--methods",
        type=_methods,
        default=None,
        help=f"comma-separated methods to measure on the same splits, from: "
        f"{', '.join(sorted(METHODS))} (default: the service's default method, {DEFAULT_METHOD})",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=Path("results.json"),
        help="where to write the results JSON (default: %(default)s)",
    )
    p.add_argument(
        "--report",
        type=Path,
        default=None,
        metavar="DIR",
        help="also write report.md (our figures beside the paper's tables) and the "
        "Fig. 7/8 PNGs into this folder",
    )
    p.add_argument(
        "--test-trials",
        type=_positive,
        default=None,
        help="trials held out per known object as its test data, the rest train "
        "(default: 2; for raw trials: 3)",
    )
    p.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="METHOD.NAME=VALUE",
        help="a method's hyper-parameter, e.g. --param paper.encoder_epochs=30 (repeatable; "
        "the value is parsed as JSON)",
    )
    p.add_argument(
        "--validation",
        action="store_true",
        help="raw trials only: measure on validation trials carved from each split's "
        "training trials (and, per held-out pressure, fit on one other pressure and "
        "validate on the other), never on test trials: where options are chosen",
    )
    p.add_argument(
        "--no-pressure",
        action="store_true",
        help="raw trials only: leave out the held-out grip pressure protocol",
    )
    p.add_argument(
        "--distinct-from-known",
        action="store_true",
        help="also require every novel object's attribute vector to differ from every "
        "known object's (by default novel vectors need only differ from each other, "
        "as in the paper)",
    )
    p.add_argument(
        "--data-seed",
        type=int,
        default=0,
        help="seed of the simulated dataset, ignored for PHAC-2 (default: %(default)s)",
    )
    p.add_argument(
        "--jobs",
        type=_positive,
        default=None,
        metavar="N",
        help="worker processes that run splits side by side; every split gets the same seeds "
        "as with --jobs 1, so the figures are the same (default: the number of cores, "
        f"{default_jobs()} here; the raw-trial protocol runs in one process)",
    )
    p.add_argument(
        "--rerun-splits",
        type=_positive,
        default=None,
        metavar="N",
        help="the size of the re-run whose landing range is reported beside every mean: "
        "where the mean of the same command on another --seed with N splits lands, 95%% "
        "(default: --splits)",
    )
    p.add_argument(
        "--ceilings",
        action="store_true",
        help="also measure limits on the same splits: nd_test_kept and nd_balance (known test "
        "trials kept at the tuned threshold; the smaller of that and nd_novel_detected), "
        "ceil_nd_* at the best threshold chosen on the test samples themselves, and "
        "ceil_gzsl_seen / ceil_gzsl_unseen / ceil_gzsl_h under perfect routing (known test "
        "trials to the known-class classifier, novel ones to the zero-shot classifier)",
    )
    p.add_argument(
        "--touches",
        type=_touch_counts,
        default=[],
        metavar="K,K,...",
        help="also the figures after K touches of each test object answered as one (as "
        "POST /v1/recognize?same_object=true does), for each K, and the mixed known + novel "
        "figure after one enrolled touch per novel object (osl_gzsl_*); K up to "
        "--test-trials, which then holds out that many trials of every known object",
    )
    p.add_argument(
        "--tables",
        action="store_true",
        help="also the figures of tables of objects named jointly (app/evaluation/tables.py): "
        "tables of the novel objects with 1, 2 and 3 touches each, and tables of the novel "
        "objects and as many known ones, named jointly and one by one",
    )
    p.add_argument(
        "--procedures",
        action="store_true",
        help="also the figures against the exploratory procedures used: every subset of the "
        "dataset's procedures (each fixed order is a sequence of them), and the adaptive rule "
        "(first_procedure, then each answer's next_procedure) at several target confidences, "
        "with the share of robot time it used (app/evaluation/procedures.py); for raw BioTac "
        "trials, their phases on the trial splits, known objects only",
    )
    p.add_argument(
        "--durations",
        type=_durations,
        default={},
        metavar="NAME=SECONDS,...",
        help="seconds of robot time of procedures, for --procedures (defaults: "
        "app.data.procedures.SECONDS, whose comment gives their sources)",
    )
    p.add_argument(
        "--no-progress",
        action="store_true",
        help="hide the progress bar and the line printed on stderr per finished split",
    )
    p.set_defaults(handler=run)


def method_params(items: list[str], methods: list[str]) -> dict[str, dict]:
    """``--param METHOD.NAME=VALUE`` items as {method: {name: value}} (values parsed as JSON)."""
    from app.cli.train import parse_params

    out: dict[str, dict] = {}
    for item in items:
        key, sep, value = item.partition("=")
        method, dot, name = key.partition(".")
        if not sep or not dot or not method or not name:
            raise ValueError(f"--param expects METHOD.NAME=VALUE, got {item!r}")
        if method not in methods:
            raise ValueError(
                f"--param {item!r} names method {method!r}, which is not among --methods "
                f"({', '.join(methods)})"
            )
        out.setdefault(method, {}).update(parse_params([f"{name}={value}"]))
    return out


def run(args: argparse.Namespace) -> int:
    from app.data.biotac import BioTacDataset
    from app.data.sources import open_dataset
    from app.evaluation.protocol import evaluate
    from app.evaluation.raw import evaluate_raw
    from app.evaluation.report import write_report
    from app.framework.registry import DEFAULT_METHOD
    from app.framework.runtime import configure_threads

    configure_threads()  # TACTILE_TORCH_THREADS, else one thread (see app.framework.runtime)
    methods = args.methods or [DEFAULT_METHOD]
    params = method_params(args.param, methods)
    dataset = open_dataset(args.dataset, seed=args.data_seed)
    if isinstance(dataset, BioTacDataset):
        if args.ceilings or args.touches or args.rerun_splits or args.tables:
            raise ValueError(
                "--ceilings, --touches and --rerun-splits apply to known/novel splits, as "
                "--tables does, not to raw BioTac trials"
            )
        results = evaluate_raw(
            dataset,
            methods,
            n_splits=args.splits or 10,
            seed=args.seed,
            test_trials=args.test_trials or 3,
            method_params=params,
            progress=not args.no_progress,
            dataset_label=args.dataset,
            held_out_pressure=not args.no_pressure,
            validation=args.validation,
            procedures_measured=args.procedures,
            durations=args.durations,
        )
    else:
        results = evaluate(
            dataset,
            methods,
            n_novel=args.novel,
            n_splits=args.splits or 7,
            seed=args.seed,
            test_trials=args.test_trials or 2,
            method_params=params,
            progress=not args.no_progress,
            dataset_label=args.dataset,
            distinct_from_known=args.distinct_from_known,
            jobs=args.jobs or default_jobs(),
            ceilings=args.ceilings,
            touches=args.touches,
            rerun_splits=args.rerun_splits,
            procedures=args.procedures,
            durations=args.durations,
            tables=args.tables,
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1))
    print(summary_table(results))
    print(f"results written to {args.out}")
    if args.report is not None:
        files = write_report(results, args.report)
        print(f"report written to {files[0]}")
    sys.stdout.flush()
    return 0


def summary_table(results: dict) -> str:
    """The printed tables: each figure once, timings with their units, and notes on what
    was left out and why (``app.evaluation.summary``)."""
    from app.evaluation.summary import summary_table as table

    return table(results)
