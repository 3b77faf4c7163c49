"""One method's figures in two ``tactile-zsl evaluate`` runs of the same splits, paired.

    git worktree add /tmp/before COMMIT
    (cd /tmp/before && PYTHONPATH=/tmp/before .venv/bin/python -m app.cli evaluate \\
        --dataset phac2:../shared/data/phac2 --novel 6 --splits 50 --seed 1000 \\
        --methods best --out /tmp/before6.json)
    .venv/bin/tactile-zsl evaluate --dataset phac2:../shared/data/phac2 --novel 6 \\
        --splits 50 --seed 1000 --methods best --out /tmp/after6.json
    .venv/bin/python bench/paired_runs.py /tmp/before6.json /tmp/after6.json

``evaluate`` pairs methods of one run; a change to a method is measured across two runs of
two commits instead. Both runs must have drawn the same splits (the same dataset, seed,
number of splits and novel objects; checked on the split definitions). For every figure it
prints the mean of each run and their mean paired difference (after - before) with its
95 % Student-t interval over splits, and says whether that interval holds 0.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from app.evaluation.metrics import mean_interval, paired_differences


def paired_table(before: dict, after: dict, method: str) -> list[dict]:
    """Per figure: both means, the mean paired difference and its 95 % interval."""
    if before["split_definitions"] != after["split_definitions"]:
        raise ValueError("the two runs drew different splits: nothing to pair")
    a, b = before["methods"][method]["splits"], after["methods"][method]["splits"]
    rows = []
    for figure, value in a[0].items():
        if figure == "split" or not isinstance(value, int | float):
            continue
        x = [s[figure] for s in a]
        y = [s[figure] for s in b]
        d = paired_differences(y, x)
        lo, hi = mean_interval(d)
        rows.append(
            {
                "figure": figure,
                "before": float(np.nanmean(x)),
                "after": float(np.nanmean(y)),
                "difference": float(np.nanmean(d)),
                "ci95": [lo, hi],
                "holds_zero": bool(lo <= 0 <= hi) or lo != lo,  # NaN: no difference at all
            }
        )
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[1])
    p.add_argument("before", help="results.json of the earlier run")
    p.add_argument("after", help="results.json of the later run")
    p.add_argument("--method", default="best", help="the method to pair (default best)")
    args = p.parse_args(argv)
    try:
        runs = [json.loads(open(path).read()) for path in (args.before, args.after)]
        rows = paired_table(*runs, args.method)
    except (OSError, ValueError, KeyError) as exc:
        print(f"paired_runs: {exc}", file=sys.stderr)
        return 2
    print("| figure | before | after | after - before [95 % interval] |")
    print("| --- | --- | --- | --- |")
    for r in rows:
        lo, hi = r["ci95"]
        mark = "" if r["holds_zero"] else " **outside 0**"
        print(
            f"| {r['figure']} | {r['before']:.3f} | {r['after']:.3f} | "
            f"{r['difference']:+.4f} [{lo:+.4f}, {hi:+.4f}]{mark} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
