"""``tactile-zsl evaluate``: the paper's Sect. VI protocol on random known/novel splits."""

from __future__ import annotations

import argparse
import json
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
            "and their means as JSON."
        ),
    )
    p.add_argument(
        "--dataset",
        default="simulated",
        help="dataset spec: 'phac2:PATH' (PHAC-2 static features folder), 'simulated' or "
        "'simulated:N' (built-in simulator with N objects); default: %(default)s",
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
        default=7,
        help="number of random known/novel splits; the paper uses 7 (default: %(default)s)",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of the split draws and of the methods' own randomness (default: %(default)s)",
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
        default=2,
        help="trials held out per known object as its test data, the rest train "
        "(default: %(default)s)",
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
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from app.data.sources import load_dataset
    from app.evaluation.protocol import evaluate
    from app.evaluation.report import write_report
    from app.framework.registry import DEFAULT_METHOD
    from app.framework.runtime import configure_threads

    configure_threads()  # TACTILE_TORCH_THREADS, else one thread (see app.framework.runtime)
    methods = args.methods or [DEFAULT_METHOD]
    dataset = load_dataset(args.dataset, seed=args.data_seed)
    results = evaluate(
        dataset,
        methods,
        n_novel=args.novel,
        n_splits=args.splits,
        seed=args.seed,
        test_trials=args.test_trials,
        progress=not args.no_progress,
        dataset_label=args.dataset,
        distinct_from_known=args.distinct_from_known,
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
    """Mean figures per method as a plain-text table."""
    from app.evaluation.report import ORDER

    methods = list(results["methods"])
    present = {f for m in methods for f in results["methods"][m]["mean"]}
    rows = [f for f in ORDER if f in present]
    width = max(len(m) for m in methods + ["figure"]) + 2
    lines = ["figure".ljust(18) + "".join(m.rjust(width) for m in methods)]
    for f in rows:
        cells = []
        for m in methods:
            v = results["methods"][m]["mean"].get(f)
            cells.append(("—" if v is None else f"{v:.3f}").rjust(width))
        lines.append(f.ljust(18) + "".join(cells))
    lines.append(
        "seconds".ljust(18)
        + "".join(f"{results['methods'][m]['elapsed_s']:.0f}".rjust(width) for m in methods)
    )
    return "\n".join(lines)
