"""Do re-runs on seeds nobody used land inside the published intervals?

    .venv/bin/python bench/research/rerun_check.py --methods best \\
        --base docs/results/phac2-best500-novel12/results.json \\
        --base docs/results/phac2-novel12/results.json \\
        --seeds 11000,12000,13000,14000,15000,16000 \\
        --out docs/results/rerun-check-novel12.json --plot docs/results/rerun-check-novel12.png

Each ``--base`` is a published ``tactile-zsl evaluate`` results file (``rerun95`` in it, so
written since 351c88d); all of them of the same number of novel objects, held-out trials
and re-run size. For each of ``--seeds`` this runs that evaluation once (``--methods``,
default the first base's, on ``--data``) with the bases' ``rerun_splits`` splits, and says
for every base and figure whether the re-run's mean landed inside the base's ``rerun95``
(where a re-run should land, 95 %) and inside its ``ci95`` (the interval of the true mean,
which catches re-runs less often). It prints a markdown table per base, writes the JSON
report to ``--out`` and, per base, a PNG of the first method to ``--plot`` (``-2``, ``-3``,
… before the suffix for the later bases).

The seeds must be ones no development run and no published table used; the check is only
worth its seeds. ``--tiny`` (the smoke test) runs one split of the first seed.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from app.data.sources import open_dataset
from app.evaluation.protocol import evaluate

DEFAULT_DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "phac2"


def check(base: dict, reruns: dict[int, dict]) -> dict:
    """Per method and figure: the base's mean, ``ci95`` and ``rerun95``, each re-run's
    mean, and how many re-runs landed inside each interval."""
    out: dict = {}
    for method, entry in base["methods"].items():
        if not all(method in run["methods"] for run in reruns.values()):
            continue
        figures = {}
        for f, mean in entry["mean"].items():
            if not all(f in run["methods"][method]["mean"] for run in reruns.values()):
                continue  # a figure the re-runs do not measure (--ceilings, --touches)
            lo, hi = entry["rerun95"][f]
            c_lo, c_hi = entry["ci95"][f]
            means = {seed: run["methods"][method]["mean"][f] for seed, run in reruns.items()}
            finite = [m for m in means.values() if m is not None and np.isfinite(m)]
            if mean is None or not np.isfinite(mean) or not finite:
                continue
            figures[f] = {
                "base_mean": mean,
                "ci95": [c_lo, c_hi],
                "rerun95": [lo, hi],
                "reruns": {str(s): m for s, m in means.items()},
                "inside_rerun95": int(sum(lo <= m <= hi for m in finite)),
                "inside_ci95": int(sum(c_lo <= m <= c_hi for m in finite)),
                "checked": len(finite),
            }
        out[method] = figures
    return out


def table(report: dict) -> str:
    """A markdown table per method: the published figure, its re-run range, each seed's
    mean (**bold** when outside the range) and the count inside."""
    lines = []
    seeds = report["seeds"]
    for method, figures in report["methods"].items():
        lines += [
            f"`{method}`, {report['novel']} novel objects: published over "
            f"{report['base_splits']} splits (seed {report['base_seed']}), re-runs of "
            f"{report['rerun_splits']} splits",
            "",
            "| figure | published mean [95 % CI] | a re-run lands in | "
            + " | ".join(f"seed {s}" for s in seeds)
            + " | inside the re-run range | inside the CI |",
            "| --- | --- | --- | " + " | ".join("---" for _ in seeds) + " | --- | --- |",
        ]
        for f, row in figures.items():
            lo, hi = row["rerun95"]
            cells = []
            for s in seeds:
                m = row["reruns"][str(s)]
                cells.append(f"{m:.3f}" if lo <= m <= hi else f"**{m:.3f}**")
            lines.append(
                f"| `{f}` | {row['base_mean']:.3f} [{row['ci95'][0]:.3f}, {row['ci95'][1]:.3f}]"
                f" | [{lo:.3f}, {hi:.3f}] | "
                + " | ".join(cells)
                + f" | {row['inside_rerun95']}/{row['checked']}"
                f" | {row['inside_ci95']}/{row['checked']} |"
            )
        inside = sum(r["inside_rerun95"] for r in figures.values())
        total = sum(r["checked"] for r in figures.values())
        inside_ci = sum(r["inside_ci95"] for r in figures.values())
        lines += [
            "",
            f"Inside the re-run range: {inside} of {total}; inside the confidence interval: "
            f"{inside_ci} of {total}.",
            "",
        ]
    return "\n".join(lines)


def plot(report: dict, path: Path) -> None:
    """One panel per figure: the published mean, its CI (dark) and re-run range (light),
    and each re-run's mean as a dot (red when outside the range)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    method, figures = next(iter(report["methods"].items()))
    names = list(figures)
    cols = min(5, len(names))
    rows = -(-len(names) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.0 * cols, 2.6 * rows), squeeze=False)
    for ax, f in zip(axes.flat, names, strict=False):
        row = figures[f]
        ax.axhspan(*row["rerun95"], color="tab:blue", alpha=0.15, label="a re-run lands in")
        ax.axhspan(*row["ci95"], color="tab:blue", alpha=0.35, label="95 % CI")
        ax.axhline(row["base_mean"], color="tab:blue", lw=1.2, label="published mean")
        xs = np.arange(len(report["seeds"]))
        ys = [row["reruns"][str(s)] for s in report["seeds"]]
        colors = ["tab:red" if not row["rerun95"][0] <= y <= row["rerun95"][1] else "k" for y in ys]
        ax.scatter(xs, ys, c=colors, s=18, zorder=3, label="re-run on an unused seed")
        ax.set_xticks(xs, [str(s) for s in report["seeds"]], rotation=90, fontsize=7)
        ax.set_title(f, fontsize=9)
        ax.tick_params(axis="y", labelsize=7)
    for ax in axes.flat[len(names) :]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=6, loc="lower left")
    fig.suptitle(
        f"{method}, {report['novel']} novel objects: {report['rerun_splits']}-split re-runs "
        f"against the {report['base_splits']}-split published intervals",
        fontsize=10,
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument(
        "--base", type=Path, action="append", required=True, help="a published results.json"
    )
    p.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the PHAC-2 folder")
    p.add_argument("--seeds", required=True, help="comma-separated unused split seeds")
    p.add_argument("--methods", help="comma-separated methods to re-run (default: the base's)")
    p.add_argument("--jobs", type=int, default=1, help="processes per evaluation")
    p.add_argument("--out", type=Path, help="the JSON report")
    p.add_argument("--plot", type=Path, help="the PNG (one per base)")
    p.add_argument("--tiny", action="store_true", help="smoke-test size: one split, one seed")
    args = p.parse_args(argv)
    bases = [json.loads(path.read_text()) for path in args.base]
    for path, base in zip(args.base, bases, strict=True):
        if "rerun_splits" not in base:
            raise SystemExit(f"{path} has no re-run ranges (written before 351c88d)")
    for key in ("novel", "test_trials", "rerun_splits"):
        if len({b[key] for b in bases}) > 1:
            raise SystemExit(f"the bases differ in {key}: {[b[key] for b in bases]}")
    seeds = [int(s) for s in args.seeds.split(",")]
    for base in bases:
        if base["seed"] in seeds:
            raise SystemExit(f"seed {base['seed']} is a published run's own")
    methods = args.methods.split(",") if args.methods else list(bases[0]["methods"])
    splits = bases[0]["rerun_splits"]
    if args.tiny:
        seeds, splits = seeds[:1], 1
    dataset = open_dataset(f"phac2:{args.data}")
    reruns = {}
    for seed in seeds:
        print(f"seed {seed}: {splits} splits", file=sys.stderr)
        reruns[seed] = evaluate(
            dataset,
            methods,
            n_novel=bases[0]["novel"],
            n_splits=splits,
            seed=seed,
            test_trials=bases[0]["test_trials"],
            jobs=args.jobs,
            progress=not args.tiny,
        )
    reports = [
        {
            "base": str(path),
            "base_seed": base["seed"],
            "base_splits": base["splits"],
            "novel": base["novel"],
            "rerun_splits": splits,
            "seeds": seeds,
            "methods": check(base, reruns),
        }
        for path, base in zip(args.base, bases, strict=True)
    ]
    print("\n".join(table(r) for r in reports))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(reports, indent=1))
    if args.plot:
        for i, report in enumerate(reports):
            suffix = "" if i == 0 else f"-{i + 1}"
            plot(report, args.plot.with_name(f"{args.plot.stem}{suffix}{args.plot.suffix}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
