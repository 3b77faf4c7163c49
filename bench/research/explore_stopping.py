"""Exploration bench: when should a robot stop exploring? Development seeds only.

``best`` answers from some procedures and names the next one (``next_procedure``). Until
2026-11-26 the service stopped once the answer's top probability reached a target
confidence; on PHAC-2 that stops after squeeze alone for most objects, and squeeze alone
makes confident mistakes. This script compares stopping rules on the same fitted models, each
at several targets, the next procedure chosen by the model's expected gain
(``ProcedureModels.next_procedures``):

- ``top``: stop when the top probability reaches the target;
- ``two``: the same, but never before two procedures;
- ``agree``: stop when the top probability reaches the target and the last procedure
  alone names the same class as all procedures so far (two procedures at least);
- ``top_per_second`` and ``two_per_second``: ``top`` and ``two`` with the next procedure
  chosen by expected gain per second of robot time. ``two_per_second`` is the service's
  rule since 2026-11-26 (``MIN_PROCEDURES``, ``TARGET_CONFIDENCE`` in
  ``app/framework/some_procedures.py``).

Prints, per rule and target, the mean over development splits of known_acc, gzsl_h and the
share of robot time (``app.evaluation.procedures.DURATIONS``), beside all procedures'.

The figures the code and docs/RESULTS.md cite (seeds 1-2, 5 splits each):

    .venv/bin/python bench/research/explore_stopping.py --seeds 1,2 --splits 5 --novel 6 \
        --targets 0.3,0.4,0.5 --rules top_per_second,two_per_second
    .venv/bin/python bench/research/explore_stopping.py --seeds 1,2 --splits 5 --novel 6 \
        --targets 0.3,0.4,0.5 --first SQUEEZE_SET_PRESSURE_SLOW
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np
from dev_splits import add_split_arguments, enrolled_best, splits, tiny

from app.data.phac2 import load_phac2
from app.evaluation import metrics
from app.evaluation.procedures import DURATIONS, check_durations, masked

RULES = ("top", "two", "agree", "top_per_second", "two_per_second")


def explore(
    model, x: np.ndarray, rule: str, target: float, seconds: np.ndarray, first: int
) -> np.ndarray:
    """(N, P) procedures used under ``rule`` at ``target``, starting with ``first``."""
    n = len(model.procedures)
    per_second = rule.endswith("_per_second")
    cost = seconds if per_second else np.ones(n)
    used = np.zeros((len(x), n), bool)
    used[:, first] = True
    last = np.full(len(x), first)
    active = np.arange(len(x))
    while len(active):
        partial = masked(x[active], used[active])
        batch = model.recognize_batch(partial, 1, None, 1.0)
        sure = batch.top_probability[:, 0] >= target
        count = used[active].sum(axis=1)
        if rule in ("two", "two_per_second"):
            sure &= count >= 2
        elif rule == "agree":
            alone = np.zeros_like(used[active])
            alone[np.arange(len(active)), last[active]] = True
            single = model.recognize_batch(masked(x[active], alone), 1, None, 1.0)
            same = single.top_index[:, 0] == batch.top_index[:, 0]
            sure &= (count >= 2) & same
        ask = ~sure & ~used[active].all(axis=1)
        nxt = model.procedures_.next_procedures(model.known_proba(partial), used[active], ask, cost)
        go = nxt >= 0
        used[active[go], nxt[go]] = True
        last[active[go]] = nxt[go]
        active = active[go]
    return used


def figures(model, x, used, is_known, yk, true) -> tuple[float, float]:
    xm = masked(x, used)
    known_acc = metrics.argmax_accuracy(model.known_proba(xm[is_known]), yk)
    answers = model.recognize_batch(xm, top_k=1)
    predicted = [answers.class_names[i] for i in answers.top_index[:, 0]]
    return known_acc, metrics.gzsl_figures(true, predicted, is_known)["gzsl_h"]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    add_split_arguments(p)
    p.add_argument("--targets", default="0.5,0.7,0.9")
    p.add_argument("--rules", default=",".join(RULES), help=f"some of {', '.join(RULES)}")
    p.add_argument(
        "--first",
        default=None,
        help="the procedure every rule starts with (default: the model's first_procedure, "
        "the largest gain per second; until 2026-11-26 the largest gain, squeeze: "
        "SQUEEZE_SET_PRESSURE_SLOW)",
    )
    p.add_argument(
        "--params",
        type=json.loads,
        default=None,
        help="best's parameters in place of its defaults, as JSON (e.g. '{\"procedure_estimators\": 100}')",
    )
    args = tiny(p.parse_args())
    targets = [float(t) for t in args.targets.split(",")]
    data = load_phac2(args.data)
    durations = check_durations(data.procedures, DURATIONS)
    if args.first is not None and args.first not in data.procedures:
        p.error(f"--first: one of {', '.join(data.procedures)}, got {args.first!r}")
    rows: dict[str, list[tuple[float, float, float]]] = {}
    for seed, split in splits(data, args, development_only=True):
        train = split.train_dataset(data)
        model = enrolled_best(data, split, args.params)
        xk, xn = data.samples[split.known_test_idx], data.samples[split.novel_test_idx]
        yk = split.known_labels(data, split.known_test_idx)
        yn = split.novel_labels(data, split.novel_test_idx)
        true = [train.class_names[j] for j in yk] + [split.novel_names[j] for j in yn]
        x = np.concatenate([xk, xn])
        is_known = np.r_[np.ones(len(xk), bool), np.zeros(len(xn), bool)]
        every = np.ones((len(x), len(data.procedures)), bool)
        rows.setdefault("all", []).append((*figures(model, x, every, is_known, yk, true), 1.0))
        first = model.procedures.index(args.first or model.first_procedure)
        for rule in args.rules.split(","):
            for t in targets:
                used = explore(model, x, rule, t, durations, first)
                share = float((used @ durations / durations.sum()).mean())
                got = (*figures(model, x, used, is_known, yk, true), share)
                rows.setdefault(f"{rule}@{t}", []).append(got)
        print(json.dumps({"seed": seed, "split": split.index + 1}), file=sys.stderr, flush=True)
    all_k, all_h, _ = np.mean(rows["all"], axis=0)
    out = {}
    for key, values in rows.items():
        k, h, time = np.mean(values, axis=0)
        out[key] = {
            "known_acc": round(float(k), 3),
            "known_vs_all": round(float(k - all_k), 3),
            "gzsl_h": round(float(h), 3),
            "gzsl_h_vs_all": round(float(h - all_h), 3),
            "time": round(float(time), 3),
        }
    print(json.dumps({"splits_run": len(rows["all"]), "rules": out}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
