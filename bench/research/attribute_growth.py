"""Adding an attribute to a running model: leave-one-attribute-out on PHAC-2.

``TactileRecognizer.with_attributes`` (4621ea7) refits only ``best``'s attribute parts (the
per-attribute logistic classifiers, the attribute prior, the semantic autoencoder) for a
grown vocabulary and keeps the forest and the novelty detector; the service uses it when
an operator adds an attribute to a running model. This measures whether a model grown that
way recognises as well as one that had the attribute from the start.

For every split (``make_zsl_splits``: novel objects held out whole, known objects' test
trials held out whole) and every attribute A of ``--attributes`` (default: all the
dataset loader keeps, the paper's 19):

- (a) "from the start": ``best`` fitted on the known objects' training trials with every
  attribute (one model per split, shared by all A);
- (b) "added later": ``best`` fitted on the same trials described without A, then
  ``with_attributes`` with A appended to the vocabulary and the known objects' true values
  of A: what the service does when an operator adds it;
- "without" (context): the model of (b) before A was added.

Figures, on the novel objects' test trials:

- ``auc``: A's out-of-object AUC, ``attribute_proba``'s column for A against the novel
  objects' true 0/1 values of A (the project's AUROC, ``metrics.novelty_auroc``, with
  A's absent samples as the negatives); NaN (skipped) on a split where A is constant over
  the novel objects;
- ``zsl``: zero-shot accuracy of the novel objects enrolled with every attribute (in (b)
  A last, as the grown vocabulary orders it); "without": enrolled without A, NaN on a
  split where two novel objects then share a vector, or one has none left (they cannot
  be enrolled).

Per attribute: each figure's mean and 95 % t interval over splits under both conditions
(``protocol.summarize_entry``) and the paired difference (b - a) with its interval and the
splits won / lost (``protocol.paired_entry``), as ``tactile-zsl evaluate`` reports
methods. The intervals treat splits as independent draws; they share objects and trials,
so the intervals understate the uncertainty about new objects (``protocol.INTERVALS``).

Split seed: 7 by default, a seed no development run used (1000 is the reporting seed of
docs/RESULTS.md's tables from 2026-11-24 on, 0 the one before; 1-5 were used for
development and confirmation).

    .venv/bin/python -m bench.research.attribute_growth            # seed 7, 20 splits, 6 novel
    .venv/bin/python -m bench.research.attribute_growth --tiny     # smoke-test size

Writes the per-split figures and summaries as JSON (``--out``, default
docs/results/attribute_growth.json) and a PNG (``--plot``, default
docs/results/attribute_growth.png): per attribute, AUC (a) against (b), and the paired zsl
differences (b - a) and (without - a).

Results (2026-11-24, on 5ad9630 with this script; 2-core shared machine, one process,
n_jobs 1, 497 s; seed 7, 20 splits, 6 novel; all 19 attributes): (b) equals (a) in every
figure of every split: AUC and zsl differences 0 (0 splits won or lost), the attribute's
probability and the novel posterior within 1.1e-6 of (a)'s (float32 products with the
attribute in another column; 0 for ``thick``, already last). Split-to-split noise: zsl
0.478 [0.408, 0.547]; AUC intervals 0.15 wide on average. Without the attribute, zsl moves
by -0.028 (``thick``) to +0.021 (``squishy``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # dev_splits, also under python -m

from dev_splits import add_split_arguments, splits, tiny  # noqa: E402

from app.data.phac2 import load_phac2  # noqa: E402
from app.evaluation import metrics  # noqa: E402
from app.evaluation.protocol import (  # noqa: E402
    INTERVALS,
    make_recognizer,
    paired_entry,
    summarize_entry,
)
from app.framework.errors import AttributeVectorError, DuplicateClassError  # noqa: E402
from app.framework.jsonable import jsonable  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
FIGURES = ("auc", "zsl")
# (a), (b), (b) before the attribute is added, and (b) with the objects not given a value
# counted as 0 (what a store without "not known" would do; equal to (b) at --known-share 1)
CONDITIONS = ("start", "later", "without", "zeroed")


def attribute_auc(proba: np.ndarray, truth: np.ndarray) -> float:
    """AUROC of one attribute's probabilities against its true 0/1 values; NaN where the
    values are constant (no AUC exists)."""
    present = np.asarray(truth) > 0.5
    if present.all() or not present.any():
        return math.nan
    return metrics.novelty_auroc(proba[~present], proba[present])


def zero_shot(
    model, names: list[str], vectors: np.ndarray, xn, may_fail: bool = False
) -> np.ndarray | None:
    """``novel_proba`` of the novel test samples ``xn`` with the novel classes enrolled from
    ``vectors``, as ``protocol.evaluate_split`` enrols them for ``zsl``. ``may_fail``: None
    where the vectors cannot be enrolled (two coincide, or one is empty), as without an
    attribute they may."""
    try:
        enrolled = model.add_novel_classes(names, vectors, allow_known_vectors=True)
    except (DuplicateClassError, AttributeVectorError):
        if may_fail:
            return None
        raise
    return enrolled.novel_proba(xn)


def zsl(proba: np.ndarray | None, yn: np.ndarray) -> float:
    """Zero-shot accuracy (``protocol``'s ``zsl``); NaN where nothing could be enrolled."""
    return math.nan if proba is None else metrics.accuracy(yn, proba.argmax(axis=1))


def run_split(
    dataset, seed: int, split, attributes: list[str], params: dict, known_share: float = 1.0
) -> dict:
    """Every condition's figures for every attribute on one split. ``known_share``: the
    share of known objects the operator gives A's value for (drawn per split and attribute);
    the others are not known for A in (b) and 0 in "zeroed"."""
    names = list(dataset.attribute_names)
    rng = np.random.default_rng([seed, split.index])
    train = split.train_dataset(dataset)
    values = train.attribute_values  # (known classes, M): the training objects' true values
    xn = dataset.samples[split.novel_test_idx]
    yn = split.novel_labels(dataset, split.novel_test_idx)
    novel_names = list(split.novel_names)
    novel_vectors = split.novel_attributes(dataset).astype(np.float64)

    # (a): every attribute from the start
    start = make_recognizer("best", params, 0).fit(train)
    p_start = start.attribute_proba(xn)
    z_start = zero_shot(start, novel_names, novel_vectors, xn)
    label = f"{seed}/{split.index + 1}"
    row: dict = {"split": label, "novel_objects": list(split.novel_objects), "attributes": {}}
    for attribute in attributes:
        j = names.index(attribute)
        rest = [i for i in range(len(names)) if i != j]
        grown = [*rest, j]  # the operator's new attribute comes last
        truth = novel_vectors[yn, j]
        # (b): fitted without the attribute, then grown by with_attributes
        without = make_recognizer("best", params, 0).fit(
            train.with_attributes([names[i] for i in rest], values[:, rest])
        )
        given = values[:, grown].copy()
        told = rng.random(len(given)) < known_share
        told[rng.integers(len(told))] = True  # at least one object's value
        given[~told, -1] = np.nan
        later = without.with_attributes(train.with_attributes([names[i] for i in grown], given))
        assert later.registry.attribute_names == tuple(names[i] for i in grown)
        p_later = later.attribute_proba(xn)
        z_later = zero_shot(later, novel_names, novel_vectors[:, grown], xn)
        zeroed = without.with_attributes(
            train.with_attributes([names[i] for i in grown], np.nan_to_num(given))
        )
        p_zeroed = zeroed.attribute_proba(xn)
        z_zeroed = zero_shot(zeroed, novel_names, novel_vectors[:, grown], xn)
        z_without = zero_shot(without, novel_names, novel_vectors[:, rest], xn, may_fail=True)
        row["attributes"][attribute] = {
            "start": {"auc": attribute_auc(p_start[:, j], truth), "zsl": zsl(z_start, yn)},
            "later": {"auc": attribute_auc(p_later[:, -1], truth), "zsl": zsl(z_later, yn)},
            "without": {"auc": math.nan, "zsl": zsl(z_without, yn)},
            "zeroed": {"auc": attribute_auc(p_zeroed[:, -1], truth), "zsl": zsl(z_zeroed, yn)},
            "objects_given": int(told.sum()),
            # how far (b) is from (a) before any figure: the attribute's probability and
            # the novel classes' posterior, on every novel test sample
            "max_abs_proba_diff": float(np.abs(p_later[:, -1] - p_start[:, j]).max()),
            "max_abs_novel_proba_diff": float(np.abs(z_later - z_start).max()),
        }
    return row


def summarize(rows: list[dict], attributes: list[str]) -> dict:
    """Per attribute and condition: mean, std and ci95 of each figure; paired (b - a) and
    (without - a) differences."""
    out = {}
    for attribute in attributes:
        entries = {
            c: {"splits": [{"split": r["split"], **r["attributes"][attribute][c]} for r in rows]}
            for c in CONDITIONS
        }
        for entry in entries.values():
            summarize_entry(entry, FIGURES)
        gaps = {
            k: float(max(r["attributes"][attribute][k] for r in rows))
            for k in ("max_abs_proba_diff", "max_abs_novel_proba_diff")
        }
        out[attribute] = {
            **{c: {k: e[k] for k in ("mean", "std", "ci95")} for c, e in entries.items()},
            "auc_splits_used": int(sum(np.isfinite(s["auc"]) for s in entries["start"]["splits"])),
            "later_minus_start": paired_entry(entries["later"], entries["start"]),
            "without_minus_start": paired_entry(entries["without"], entries["start"]),
            "later_minus_zeroed": paired_entry(entries["later"], entries["zeroed"]),
            "zsl_splits_without": int(
                sum(np.isfinite(s["zsl"]) for s in entries["without"]["splits"])
            ),
            **gaps,
        }
    return out


def pooled(summary: dict) -> dict:
    """Over attributes: the largest |mean paired difference (b - a)| of each figure and the
    mean width of the (a) intervals (the split-to-split noise it is measured against)."""
    out = {}
    for f in FIGURES:
        d = [s["later_minus_start"]["mean"][f] for s in summary.values()]
        width = [np.subtract(*s["start"]["ci95"][f][::-1]) for s in summary.values()]
        out[f] = {
            "max_abs_mean_difference": float(np.nanmax(np.abs(d))),
            "mean_ci95_width_start": float(np.nanmean(width)) if np.isfinite(width).any() else None,
            "splits_won": int(sum(s["later_minus_start"]["won"][f] for s in summary.values())),
            "splits_lost": int(sum(s["later_minus_start"]["lost"][f] for s in summary.values())),
        }
    for k in ("max_abs_proba_diff", "max_abs_novel_proba_diff"):
        out[k] = float(max(s[k] for s in summary.values()))
    return out


def fmt(mean: float, ci: list[float], digits: int = 3) -> str:
    if not np.isfinite(mean):
        return "—"
    if not np.isfinite(ci).all():  # one split: no interval
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} [{ci[0]:.{digits}f}, {ci[1]:.{digits}f}]"


def table(summary: dict) -> str:
    """The Markdown table of the report (docs/RESULTS.md's layout)."""
    lines = [
        "| attribute | splits (AUC) | AUC (a) start | AUC (b) added later | AUC b − a "
        "| zsl (a) start | zsl (b) added later | zsl b − a | zsl without − a (splits) |",
        "| --- | ---: | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for attribute, s in summary.items():
        d, w = s["later_minus_start"], s["without_minus_start"]
        lines.append(
            f"| {attribute} | {s['auc_splits_used']} "
            f"| {fmt(s['start']['mean']['auc'], s['start']['ci95']['auc'])} "
            f"| {fmt(s['later']['mean']['auc'], s['later']['ci95']['auc'])} "
            f"| {fmt(d['mean']['auc'], d['ci95']['auc'], 4)} "
            f"| {fmt(s['start']['mean']['zsl'], s['start']['ci95']['zsl'])} "
            f"| {fmt(s['later']['mean']['zsl'], s['later']['ci95']['zsl'])} "
            f"| {fmt(d['mean']['zsl'], d['ci95']['zsl'], 4)} "
            f"| {fmt(w['mean']['zsl'], w['ci95']['zsl'])} ({s['zsl_splits_without']}) |"
        )
    return "\n".join(lines)


def table_partial(summary: dict) -> str:
    """With ``--known-share`` below 1: the objects not given a value left out of the
    attribute's training (b) against counted as 0 ("zeroed")."""
    lines = [
        "| attribute | AUC (a) start | AUC (b) others not known | AUC others counted 0 "
        "| AUC (b) − counted 0 | zsl (b) − counted 0 |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for attribute, s in summary.items():
        d = s["later_minus_zeroed"]
        lines.append(
            f"| {attribute} | {fmt(s['start']['mean']['auc'], s['start']['ci95']['auc'])} "
            f"| {fmt(s['later']['mean']['auc'], s['later']['ci95']['auc'])} "
            f"| {fmt(s['zeroed']['mean']['auc'], s['zeroed']['ci95']['auc'])} "
            f"| {fmt(d['mean']['auc'], d['ci95']['auc'], 4)} "
            f"| {fmt(d['mean']['zsl'], d['ci95']['zsl'], 4)} |"
        )
    return "\n".join(lines)


def plot(summary: dict, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(summary)
    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 6), gridspec_kw={"width_ratios": [1, 1.3]})
    a = np.array([summary[n]["start"]["mean"]["auc"] for n in names])
    b = np.array([summary[n]["later"]["mean"]["auc"] for n in names])
    a_ci = np.array([summary[n]["start"]["ci95"]["auc"] for n in names], dtype=float)
    b_ci = np.array([summary[n]["later"]["ci95"]["auc"] for n in names], dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    left.errorbar(
        a[ok],
        b[ok],
        xerr=np.abs(a_ci[ok].T - a[ok]),
        yerr=np.abs(b_ci[ok].T - b[ok]),
        fmt="o",
        ms=4,
        elinewidth=0.6,
        capsize=2,
    )
    for n, x, y in zip(np.array(names)[ok], a[ok], b[ok], strict=True):
        left.annotate(n, (x, y), xytext=(3, -9), textcoords="offset points", fontsize=7)
    low = float(np.nanmin(np.r_[a_ci[ok].ravel(), b_ci[ok].ravel(), 0.5])) - 0.02
    left.plot([low, 1], [low, 1], color="grey", lw=0.8, ls="--")
    left.set(
        xlim=(low, 1),
        ylim=(low, 1),
        xlabel="(a) from the start: out-of-object AUC",
        ylabel="(b) added later by with_attributes: AUC",
        title="the attribute's AUC on the novel objects (mean, 95% CI over splits)",
    )
    y = np.arange(len(names))
    for offset, key, label in (
        (-0.15, "later_minus_start", "zsl (b) − (a)"),
        (0.15, "without_minus_start", "zsl without the attribute − (a)"),
    ):
        m = np.array([summary[n][key]["mean"]["zsl"] for n in names])
        ci = np.array([summary[n][key]["ci95"]["zsl"] for n in names], dtype=float)
        right.errorbar(m, y + offset, xerr=np.abs(ci.T - m), fmt="o", ms=4, capsize=2, label=label)
    right.axvline(0, color="grey", lw=0.8)
    right.set_yticks(y, names, fontsize=8)
    right.invert_yaxis()
    right.set(
        xlabel="paired difference in zero-shot accuracy (mean, 95% CI)",
        title="zsl of the novel objects",
    )
    right.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=2)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


def commit() -> str:
    try:
        return subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            cwd=ROOT,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_split_arguments(ap)
    ap.set_defaults(seeds="7", splits=20)
    ap.add_argument(
        "--attributes",
        default="",
        help="comma-separated attributes to leave out in turn (default: all the loader keeps)",
    )
    ap.add_argument(
        "--params", default="{}", help="best's parameters as JSON (default: its defaults)"
    )
    ap.add_argument(
        "--known-share",
        type=float,
        default=1.0,
        help="share of the known objects given the added attribute's value (the rest: not "
        "known); default 1: every one, the true values",
    )
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "attribute_growth.json")
    ap.add_argument("--plot", type=Path, default=ROOT / "docs" / "results" / "attribute_growth.png")
    args = ap.parse_args()
    params = {"n_jobs": 1, **json.loads(args.params)}
    if args.tiny:  # two attributes, a small forest, one tuning round: seconds
        params.update(n_estimators=10, tuning_rounds=1)
        args.attributes = args.attributes or "hard,smooth"
    args = tiny(args)
    if not 0 < args.known_share <= 1:
        ap.error(f"--known-share must be in (0, 1], got {args.known_share}")
    if {0, 5} & {int(s) for s in args.seeds.split(",")}:
        print("note: seeds 0 and 5 were used by development runs", file=sys.stderr)

    dataset = load_phac2(args.data)
    attributes = [a for a in args.attributes.split(",") if a] or list(dataset.attribute_names)
    unknown = sorted(set(attributes) - set(dataset.attribute_names))
    if unknown:
        raise SystemExit(f"unknown attributes {unknown}; the dataset has {dataset.attribute_names}")

    started = time.perf_counter()
    rows = []
    for seed, split in splits(dataset, args):
        t = time.perf_counter()
        rows.append(run_split(dataset, seed, split, attributes, params, args.known_share))
        print(
            f"split {rows[-1]['split']} done in {time.perf_counter() - t:.0f} s",
            file=sys.stderr,
            flush=True,
        )
    summary = summarize(rows, attributes)
    elapsed = time.perf_counter() - started
    report = {
        "commit": commit(),
        "command": " ".join(["python -m bench.research.attribute_growth", *sys.argv[1:]]),
        "seeds": args.seeds,
        "splits_per_seed": args.splits,
        "splits_run": len(rows),
        "novel": args.novel,
        "known_share": args.known_share,
        "params": params,
        "attributes": attributes,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
        "elapsed_s": round(elapsed, 1),
        "intervals": INTERVALS,
        "pooled": pooled(summary),
        "per_attribute": summary,
        "rows": rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(jsonable(report), indent=1) + "\n")
    plot(
        summary,
        args.plot,
        f"best, leave-one-attribute-out on PHAC-2: {len(rows)} splits of seed(s) {args.seeds}, "
        f"{args.novel} novel objects ({report['commit']})",
    )
    print(table(summary))
    if args.known_share < 1:
        print(table_partial(summary))
    print(json.dumps(jsonable({"pooled": report["pooled"], "splits_run": len(rows)}), indent=1))
    print(f"{len(rows)} splits, {len(attributes)} attributes, {elapsed:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
