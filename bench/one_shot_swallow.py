"""How often a class learnt from one sample takes touches that belong to other objects.

    .venv/bin/python -m bench.one_shot_swallow [--phac2 ../shared/data/phac2] [--splits 20]
                                              [--seed 21] [--novel 6] [--shots 3]
                                              [--methods best,prototypes]
                                              [--margins best=none,0.1 prototypes=none,5]
                                              [--out docs/results/one_shot_swallow]

On PHAC-2 and on the simulator (``simulate_dataset``, 60 objects, the split seed as its
seed), splits as ``tactile-zsl evaluate`` draws them (``make_zsl_splits``: ``--novel``
objects held out whole, 2 trials of every known object held out; each split's method seed
``split_method_seed``). The method is fitted once a split on the known objects' training
trials. Of the split's novel objects, ``--shots`` (drawn from the split's method seed) are
enrolled as the service enrols a class registered from one sample without a description
(``add_novel_classes_from_samples``, the first sample of their one-shot trial); the others
are described by their attribute vectors (``add_novel_classes``). Then every held-out touch
is recognised (``recognize_batch``, the model's own threshold), and per split:

- ``swallow_described``: the share of the described objects' test touches answered with a
  one-shot class;
- ``swallow_known``: the share of the known objects' held-out trials answered with one (only
  touches routed novel can be);
- ``own_recall``: the share of the one-shot objects' other trials answered with their own
  class;
- ``described_acc``: the share of the described objects' touches answered right.

Each is reported as the mean over the splits with its 95 % interval, for every value of the
method's ``shot_margin`` in ``--margins`` (``none``: no bound, as before 2026-11-28;
``default``: the constructor's default); the model is fitted once and enrolled again per
value, so the values are compared on the same splits. ``one_shot_swallow.json`` in ``--out``
holds every split's figures, the machine and the commit; ``one_shot_swallow.png`` draws the
swallowed share and the own recall against the margin. A Markdown table goes to stdout,
progress to stderr.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from bench.scale import machine

FIGURES = ("swallow_described", "swallow_known", "own_recall", "described_acc")
DATASETS = ("phac2", "simulator")


def say(msg: str) -> None:
    print(f"one_shot_swallow: {msg}", file=sys.stderr, flush=True)


def margin_list(text: str) -> tuple[str, list[float | None | str]]:
    """``METHOD=v1,v2,...`` with each value a number, ``none`` or ``default``."""
    method, sep, values = text.partition("=")
    if not sep or not method.strip() or not values.strip():
        raise argparse.ArgumentTypeError(f"expected METHOD=v1,v2,..., got {text!r}")
    out: list[float | None | str] = []
    for v in values.split(","):
        v = v.strip().lower()
        if v == "none":
            out.append(None)
        elif v == "default":
            out.append("default")
        else:
            try:
                number = float(v)
            except ValueError:
                raise argparse.ArgumentTypeError(
                    f"{method}: {v!r} is not a number, 'none' or 'default'"
                ) from None
            if not np.isfinite(number) or number < 0:
                raise argparse.ArgumentTypeError(f"{method}: a margin must be >= 0, got {v!r}")
            out.append(number)
    return method.strip(), out


def answers(model, x: np.ndarray) -> np.ndarray:
    """The top class name of each touch."""
    batch = model.recognize_batch(x, top_k=1)
    return np.asarray(batch.class_names, dtype=object)[batch.top_index[:, 0]]


def figures(model, dataset, split, shot: np.ndarray, described: np.ndarray) -> dict:
    """The four figures (module docstring) of ``model``, enrolled, on one split."""
    names = np.asarray(split.novel_names, dtype=object)
    shot_names = set(names[shot].tolist())
    truth = names[split.novel_labels(dataset, split.novel_test_idx)]
    got = answers(model, dataset.samples[split.novel_test_idx])
    is_shot = np.isin(truth, list(shot_names))
    known = answers(model, dataset.samples[split.known_test_idx])
    return {
        "swallow_described": float(np.isin(got[~is_shot], list(shot_names)).mean()),
        "swallow_known": float(np.isin(known, list(shot_names)).mean()),
        "own_recall": float((got[is_shot] == truth[is_shot]).mean()),
        "described_acc": float((got[~is_shot] == truth[~is_shot]).mean()),
        "n_described_touches": int((~is_shot).sum()),
        "n_own_touches": int(is_shot.sum()),
        "n_known_touches": int(len(known)),
    }


def one_split(dataset, split, method: str, seed: int, shots: int, margins: list) -> dict:
    from app.evaluation.protocol import make_recognizer

    t = time.perf_counter()
    model = make_recognizer(method, None, seed).fit(split.train_dataset(dataset), progress=False)
    fit_s = time.perf_counter() - t
    order = np.random.default_rng(seed).permutation(len(split.novel_classes))
    shot, described = np.sort(order[:shots]), np.sort(order[shots:])
    names = list(split.novel_names)
    default = model.get_params()["shot_margin"]
    rows = []
    for margin in margins:
        value = default if margin == "default" else margin
        model.set_params(shot_margin=value)
        enrolled = model
        if len(described):
            enrolled = enrolled.add_novel_classes(
                [names[j] for j in described],
                split.novel_attributes(dataset)[described],
                allow_known_vectors=True,
            )
        enrolled = enrolled.add_novel_classes_from_samples(
            {names[j]: dataset.samples[split.one_shot_idx[j]][None] for j in shot}
        )
        rows.append({"margin": value, **figures(enrolled, dataset, split, shot, described)})
    return {
        "index": split.index,
        "method_seed": seed,
        "one_shot_objects": [names[j] for j in shot],
        "described_objects": [names[j] for j in described],
        "fit_s": fit_s,
        "margins": rows,
    }


def summary(splits: list[dict]) -> list[dict]:
    """Per margin, each figure's mean over the splits and its 95 % interval."""
    from app.evaluation.metrics import mean_interval

    out = []
    for j, row in enumerate(splits[0]["margins"]):
        entry: dict = {"margin": row["margin"]}
        for fig in FIGURES:
            values = [s["margins"][j][fig] for s in splits]
            low, high = mean_interval(values, bounds=(0.0, 1.0))
            entry[fig] = {"mean": float(np.mean(values)), "low": low, "high": high}
        out.append(entry)
    return out


def table(report: dict) -> str:
    lines = [
        f"{report['splits']} splits of {report['novel']} novel objects ({report['shots']} "
        f"enrolled from one sample), split seed {report['seed']}",
        "",
        "| data | method | shot_margin | " + " | ".join(f"{f} [95 %]" for f in FIGURES) + " |",
        "| --- | --- | --- |" + " --- |" * len(FIGURES),
    ]
    for data, methods in report["results"].items():
        for method, result in methods.items():
            for entry in result["summary"]:
                cells = [
                    f"{entry[f]['mean']:.3f} [{entry[f]['low']:.3f}, {entry[f]['high']:.3f}]"
                    for f in FIGURES
                ]
                margin = "none" if entry["margin"] is None else f"{entry['margin']:g}"
                lines.append(f"| {data} | {method} | {margin} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(report: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cells = [(d, m) for d, methods in report["results"].items() for m in methods]
    fig, axes = plt.subplots(1, len(cells), figsize=(4.2 * len(cells), 4), squeeze=False)
    for ax, (data, method) in zip(axes[0], cells, strict=True):
        result = report["results"][data][method]
        entries = result["summary"]
        x = np.arange(len(entries))
        labels = ["none" if e["margin"] is None else f"{e['margin']:g}" for e in entries]
        for fig_name, color, label in (
            ("swallow_described", "tab:red", "described touches taken"),
            ("own_recall", "tab:blue", "own object recalled"),
            ("swallow_known", "tab:orange", "known touches taken"),
        ):
            mean = np.array([e[fig_name]["mean"] for e in entries])
            low = np.array([e[fig_name]["low"] for e in entries])
            high = np.array([e[fig_name]["high"] for e in entries])
            ax.plot(x, mean, "o-", color=color, label=label)
            ax.fill_between(x, low, high, color=color, alpha=0.2)
        ax.set_xticks(x, labels)
        ax.set_xlabel(f"shot_margin (default {result['default_margin']:g})")
        ax.set_ylim(0, 1.02)
        ax.set_title(f"{data}, {method}", fontsize=10)
    axes[0][0].set_ylabel("share of touches (one-shot class answered)")
    axes[0][0].legend(fontsize=8, loc="upper right")
    fig.suptitle(
        f"{report['splits']} splits, {report['novel']} novel objects, {report['shots']} "
        f"from one sample, split seed {report['seed']}",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--phac2", default="../shared/data/phac2", help="PHAC-2's folder")
    p.add_argument("--datasets", default=",".join(DATASETS), help="phac2, simulator or both")
    p.add_argument("--novel", type=int, default=6, help="objects held out whole a split")
    p.add_argument("--shots", type=int, default=3, help="of them, enrolled from one sample")
    p.add_argument("--splits", type=int, default=20)
    p.add_argument("--seed", type=int, default=21)
    p.add_argument("--methods", default="best,prototypes")
    p.add_argument("--margins", type=margin_list, nargs="*", default=[])
    p.add_argument("--out", type=Path, default=Path("docs/results/one_shot_swallow"))
    args = p.parse_args(argv)
    if args.splits < 2:
        p.error("--splits must be at least 2 (an interval needs two)")
    if not 1 <= args.shots < args.novel:
        p.error("--shots must lie in [1, --novel): some novel objects must be described")
    args.datasets = [d.strip() for d in args.datasets.split(",") if d.strip()]
    if not args.datasets or not set(args.datasets) <= set(DATASETS):
        p.error(f"--datasets: one or more of {', '.join(DATASETS)}")
    args.methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    from app.framework.registry import METHODS, make_method

    for m in args.methods:
        if m not in METHODS or "shot_margin" not in make_method(m).get_params():
            p.error(f"--methods {m}: not a method with a shot_margin")
    margins = dict(args.margins)
    unknown = set(margins) - set(args.methods)
    if unknown:
        p.error(f"--margins for methods not measured: {', '.join(sorted(unknown))}")
    args.margins = {m: margins.get(m, [None, "default"]) for m in args.methods}
    return args


def main(argv: list[str] | None = None) -> int:
    from app.data.phac2 import load_phac2
    from app.data.simulator import simulate_dataset
    from app.evaluation.protocol import split_method_seed
    from app.evaluation.splits import SplitError, make_zsl_splits
    from app.framework.registry import make_method

    args = parse(argv)
    loaders = {
        "phac2": lambda: load_phac2(args.phac2),
        "simulator": lambda: simulate_dataset(60, seed=args.seed),
    }
    report: dict = {
        "machine": machine(),
        "novel": args.novel,
        "shots": args.shots,
        "splits": args.splits,
        "seed": args.seed,
        "phac2": args.phac2,
        "simulator": {"n_objects": 60, "seed": args.seed},
        "results": {},
    }
    for data in args.datasets:
        try:
            dataset = loaders[data]()
            splits = make_zsl_splits(dataset, args.novel, args.splits, args.seed)
        except (SplitError, FileNotFoundError, ValueError) as exc:
            print(f"one_shot_swallow: {data}: {exc}", file=sys.stderr)
            return 2
        report["results"][data] = {}
        for method in args.methods:
            results = []
            for split in splits:
                seed = split_method_seed(args.seed, split.index)
                results.append(
                    one_split(dataset, split, method, seed, args.shots, args.margins[method])
                )
                say(f"{data}, {method}: split {split.index + 1}/{len(splits)}")
            report["results"][data][method] = {
                "default_margin": make_method(method).get_params()["shot_margin"],
                "summary": summary(results),
                "per_split": results,
            }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "one_shot_swallow.json").write_text(json.dumps(report, indent=2))
    plot(report, args.out / "one_shot_swallow.png")
    print(table(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
