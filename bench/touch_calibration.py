"""Operating points per kind of answer: the share of held-out known objects kept known,
and of unseen objects detected, at a stated ``known_kept`` for answers fusing 1 and k
touches, with the threshold read off the single touches' curve (as answered before
2026-11-28) and off the curve measured at fit on held-out answers fusing as many touches
(``NoveltyTuning.touches``, what ``recognize_batch`` reads now).

    .venv/bin/python -m bench.touch_calibration [--dataset phac2] [--novel 6] [--splits 10]
                                                [--seed 1000] [--method best]
                                                [--known-kept 0.9] [--touches 1,3]
                                                [--out results/touch-calibration/]

Splits as ``tactile-zsl evaluate --touches`` draws them (``make_zsl_splits`` with as many
held-out trials of every known object as the largest touch count, each split's method seed
``split_method_seed``); each object's held-out trials are dealt into groups of k distinct
trials (``app.evaluation.touches.touch_groups``) and each group answered once, its novelty
scores averaged (``recognize_batch`` with ``groups``). The two thresholds are applied to the
same fused scores, so the figures differ by the threshold alone. ``touch_calibration.json``
in ``--out`` holds every split's figures, the machine and the commit; a Markdown table goes
to stdout, progress to stderr.
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
    print(f"touch_calibration: {msg}", file=sys.stderr, flush=True)


def counts(text: str) -> list[int]:
    try:
        values = sorted({int(v) for v in text.split(",") if v.strip()})
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a list of integers: {text!r}") from None
    if not values or values[0] < 1:
        raise argparse.ArgumentTypeError(f"touch counts must be positive, got {text!r}")
    return values


def one_split(dataset, split, method: str, seed: int, kept: float, touches: list[int]) -> dict:
    from app.evaluation.protocol import make_recognizer
    from app.evaluation.touches import touch_groups

    t = time.perf_counter()
    model = make_recognizer(method, None, seed).fit(split.train_dataset(dataset), progress=False)
    fit_s = time.perf_counter() - t
    single = model.threshold_keeping(kept)
    rng = np.random.default_rng(seed)
    figures = []
    for idx, name in ((split.known_test_idx, "known"), (split.novel_test_idx, "novel")):
        x = dataset.samples[idx]
        objects, trials = dataset.labels[idx], np.asarray(dataset.trials)[idx]
        for k in touches:
            group, n = touch_groups(objects, trials, k, rng)
            rows = group >= 0
            batch = model.recognize_batch(x[rows], 1, groups=group[rows], known_kept=kept)
            fused = batch.novelty_score
            # "before": one threshold, the single touches' curve; "after": as answered now
            before = fused > single
            after = batch.is_novel
            share = (lambda novel: float(np.mean(~novel))) if name == "known" else np.mean
            figures.append(
                {
                    "objects": name,
                    "touches": k,
                    "groups": int(n),
                    "before": float(share(before)),
                    "after": float(share(after)),
                    "threshold_before": single,
                    "threshold_after": float(np.median(batch.novelty_threshold)),
                    "calibrated_touches": int(np.median(batch.calibrated_touches)),
                }
            )
    method_name = type(model).__name__
    return {"index": split.index, "method": method_name, "fit_s": fit_s, "figures": figures}


def summary(splits: list[dict]) -> list[dict]:
    """Per (objects, touches): each figure's mean over the splits and its 95 % interval;
    ``kept`` for known objects, ``detected`` for unseen ones."""
    from app.evaluation.metrics import mean_interval

    out = []
    for i, first in enumerate(splits[0]["figures"]):
        row = {"objects": first["objects"], "touches": first["touches"]}
        for key in ("before", "after"):
            values = [s["figures"][i][key] for s in splits]
            low, high = mean_interval(values, bounds=(0.0, 1.0))
            row[key] = {"mean": float(np.mean(values)), "low": low, "high": high}
        row["calibrated_touches"] = sorted({s["figures"][i]["calibrated_touches"] for s in splits})
        out.append(row)
    return out


def table(report: dict) -> str:
    lines = [
        f"{report['dataset']}, method {report['method']}, {report['splits']} splits "
        f"(seed {report['seed']}), {report['novel']} unseen objects each, stated share kept "
        f"{report['known_kept']:g}; mean [95 % interval]",
        "",
        "| objects | touches | single touches' curve | curve of as many touches | curve used |",
        "| --- | --- | --- | --- | --- |",
    ]
    for r in report["summary"]:
        what = "known kept" if r["objects"] == "known" else "unseen detected"
        cells = [
            f"{r[key]['mean']:.3f} [{r[key]['low']:.3f}, {r[key]['high']:.3f}]"
            for key in ("before", "after")
        ]
        used = "/".join(str(k) for k in r["calibrated_touches"])
        lines.append(f"| {what} | {r['touches']} | {cells[0]} | {cells[1]} | {used} |")
    return "\n".join(lines)


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dataset", default="phac2", help="a dataset spec of samples")
    p.add_argument("--novel", type=int, default=6, help="objects held out whole a split")
    p.add_argument("--splits", type=int, default=10)
    p.add_argument("--seed", type=int, default=1000)
    p.add_argument("--method", default="best")
    p.add_argument("--known-kept", type=float, default=0.9)
    p.add_argument("--touches", type=counts, default=[1, 3])
    p.add_argument("--out", type=Path, default=Path("results/touch-calibration"))
    args = p.parse_args(argv)
    if args.splits < 2:
        p.error("--splits must be at least 2 (an interval needs two)")
    if args.novel < 1:
        p.error("--novel must be at least 1")
    if not 0 < args.known_kept < 1:
        p.error(f"--known-kept must lie in (0, 1), got {args.known_kept}")
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
        splits = make_zsl_splits(
            dataset, args.novel, args.splits, args.seed, test_trials=max(args.touches)
        )
    except (DatasetSpecError, SplitError, FileNotFoundError, ValueError) as exc:
        print(f"touch_calibration: {exc}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    results = []
    for split in splits:
        seed = split_method_seed(args.seed, split.index)
        results.append(one_split(dataset, split, args.method, seed, args.known_kept, args.touches))
        say(f"split {split.index + 1}/{len(splits)}: {results[-1]['method']}")
    report = {
        "machine": machine(),
        "dataset": args.dataset,
        "novel": args.novel,
        "splits": len(splits),
        "seed": args.seed,
        "method": args.method,
        "known_kept": args.known_kept,
        "touches": args.touches,
        "summary": summary(results),
        "per_split": results,
    }
    (args.out / "touch_calibration.json").write_text(json.dumps(report, indent=2))
    print(table(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
