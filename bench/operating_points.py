"""Novelty operating points on data the threshold never saw: for each stated share of known
touches kept (``known_kept`` of ``recognize_batch``, ``?known_kept=`` over HTTP), the share
of held-out known trials the model keeps known and of unseen objects' trials it calls novel.

    .venv/bin/python -m bench.operating_points [--dataset phac2] [--novel 6] [--splits 10]
                                               [--seed 1000] [--method auto]
                                               [--shares 0.8,0.9,0.95,0.99]
                                               [--out results/operating-points/]

Splits as ``tactile-zsl evaluate`` draws them (``make_zsl_splits``: ``--novel`` objects held
out whole, 2 trials of every known object held out; each split's method seed
``split_method_seed``). The method is fitted once a split on the known objects' training
trials; its threshold for every share is read off the calibration curve it stored at fit,
so no figure here was tuned on the trials or objects it is measured on. Per share, and for
the model's own threshold (``share`` null, first): ``kept`` (held-out known trials called known),
``detected`` (novel objects' trials called novel), each as the mean over splits with its
95 % interval. ``operating_points.json`` in ``--out`` holds every split's figures, the
machine and the commit; ``operating_points.png`` draws kept and detected against the stated
share; a Markdown table goes to stdout, progress to stderr.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from bench.scale import machine


def say(msg: str) -> None:
    print(f"operating_points: {msg}", file=sys.stderr, flush=True)


def shares(text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a list of numbers: {text!r}") from None
    if not values or not all(0 < v < 1 for v in values):
        raise argparse.ArgumentTypeError(f"every share must lie in (0, 1), got {text!r}")
    return sorted(set(values))


def one_split(dataset, split, method: str, seed: int, kept_shares: list[float]) -> dict:
    from app.evaluation.protocol import make_recognizer

    t = time.perf_counter()
    model = make_recognizer(method, None, seed).fit(split.train_dataset(dataset), progress=False)
    # scored once; an answer at share q is novel above threshold_keeping(q), as served
    known = model.novelty_score(dataset.samples[split.known_test_idx])
    novel = model.novelty_score(dataset.samples[split.novel_test_idx])
    points = []
    for q in [None, *kept_shares]:
        threshold = model.novelty_threshold if q is None else model.threshold_keeping(q)
        points.append(
            {
                "share": q,
                "kept": float((known <= threshold).mean()),
                "detected": float((novel > threshold).mean()),
            }
        )
    return {
        "index": split.index,
        "method": type(model).__name__,
        "fit_s": time.perf_counter() - t,
        "points": points,
    }


def summary(splits: list[dict]) -> list[dict]:
    """Per operating point (``share`` None: the model's own threshold, first), each figure's
    mean over the splits and its 95 % interval."""
    from app.evaluation.metrics import mean_interval

    out = []
    for j, point in enumerate(splits[0]["points"]):
        entry = {"share": point["share"]}
        for fig in ("kept", "detected"):
            values = [s["points"][j][fig] for s in splits]
            low, high = mean_interval(values, bounds=(0.0, 1.0))
            entry[fig] = {"mean": float(np.mean(values)), "low": low, "high": high}
        out.append(entry)
    return out


def table(report: dict) -> str:
    lines = [
        f"{report['dataset']}, {report['splits']} splits of {report['novel']} novel objects, "
        f"seed {report['seed']}, method {report['method']}",
        "",
        "| stated share kept | known kept [95 %] | novel detected [95 %] |",
        "| --- | --- | --- |",
    ]
    for f in report["summary"]:
        k, d = f["kept"], f["detected"]
        point = "the model's own" if f["share"] is None else f"{f['share']:g}"
        lines.append(
            f"| {point} | {k['mean']:.3f} [{k['low']:.3f}, {k['high']:.3f}] | "
            f"{d['mean']:.3f} [{d['low']:.3f}, {d['high']:.3f}] |"
        )
    return "\n".join(lines)


def plot(report: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    points = {f["share"]: f for f in report["summary"] if f["share"] is not None}
    q = np.array(sorted(points))
    fig, ax = plt.subplots(figsize=(6, 4.2))
    ax.plot([q.min(), 1], [q.min(), 1], color="0.6", ls=":", label="kept = stated")
    for fig_name, color in (("kept", "tab:blue"), ("detected", "tab:red")):
        mean = np.array([points[v][fig_name]["mean"] for v in q])
        low = np.array([points[v][fig_name]["low"] for v in q])
        high = np.array([points[v][fig_name]["high"] for v in q])
        label = "held-out known trials kept" if fig_name == "kept" else "unseen objects detected"
        ax.plot(q, mean, "o-", color=color, label=label)
        ax.fill_between(q, low, high, color=color, alpha=0.2)
    ax.set_xlabel("stated share of known touches kept (known_kept)")
    ax.set_ylabel("share of test trials")
    ax.set_ylim(0, 1.02)
    ax.set_title(
        f"{report['dataset']}: {report['splits']} splits, {report['novel']} novel objects each",
        fontsize=10,
    )
    ax.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dataset", default="phac2", help="a dataset spec of samples")
    p.add_argument("--novel", type=int, default=6, help="objects held out whole a split")
    p.add_argument("--splits", type=int, default=10)
    p.add_argument("--seed", type=int, default=1000)
    p.add_argument("--method", default="auto")
    p.add_argument("--shares", type=shares, default=[0.8, 0.9, 0.95, 0.99])
    p.add_argument("--out", type=Path, default=Path("results/operating-points"))
    args = p.parse_args(argv)
    if args.splits < 2:
        p.error("--splits must be at least 2 (an interval needs two)")
    if args.novel < 1:
        p.error("--novel must be at least 1")
    from app.framework.registry import METHODS

    if args.method not in METHODS:
        p.error(f"--method {args.method}: not one of {', '.join(sorted(METHODS))}")
    return args


def main(argv: list[str] | None = None) -> int:
    from app.data.sources import DatasetSpecError, load_dataset
    from app.evaluation.protocol import split_method_seed
    from app.evaluation.splits import SplitError, make_zsl_splits

    args = parse(argv)
    try:
        dataset = load_dataset(args.dataset)
        splits = make_zsl_splits(dataset, args.novel, args.splits, args.seed)
    except (DatasetSpecError, SplitError, FileNotFoundError, ValueError) as exc:
        print(f"operating_points: {exc}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    results = []
    for split in splits:
        seed = split_method_seed(args.seed, split.index)
        results.append(one_split(dataset, split, args.method, seed, args.shares))
        say(f"split {split.index + 1}/{len(splits)}: {results[-1]['method']}")
    report = {
        "machine": machine(),
        "dataset": args.dataset,
        "novel": args.novel,
        "splits": len(splits),
        "seed": args.seed,
        "method": args.method,
        "shares": args.shares,
        "summary": summary(results),
        "per_split": results,
    }
    (args.out / "operating_points.json").write_text(json.dumps(report, indent=2))
    plot(report, args.out / "operating_points.png")
    print(table(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
