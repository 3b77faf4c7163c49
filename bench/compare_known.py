"""Known-object accuracy of candidate representations on the same splits of several data
sets: the simulator as it is, with contact modes, and PHAC-2's real trials.

    .venv/bin/python -m bench.compare_known [--sizes 300,1000] [--folds 5] [--seed 0]
                                            [--candidates best,prototypes,...]
                                            [--out results/compare_known/]

Candidates, each fitted on the same training trials and scored on the same held-out ones:

- ``best``: the forest method (``app.methods.best``, its defaults);
- ``prototypes``: ``app.methods.prototypes`` (its defaults: contact modes found per class);
- ``prototypes-1mode``: the same with ``max_modes=1``: shrinkage LDA's space under
  nearest-class-mean prototypes;
- ``lda``: scikit-learn's ``LinearDiscriminantAnalysis(solver="lsqr", shrinkage="auto")``;
- ``nn1``: one nearest training sample, Euclidean;
- ``cosface``: a learned embedding, an MLP (inputs -> 512 -> 128, ReLU) trained with a
  cosine-margin loss (CosFace: scale 16, margin 0.2; Adam, 60 epochs, batches of 256,
  weight decay 1e-4), under class prototypes (normalised class means; cosine nearest).
  Those settings were set once, before any figure here, and not tuned.

Data sets (every one held out by whole trials):

- ``sim-N``: ``simulate_dataset(N, 10)``, the last 2 trials of each object held out;
- ``sim-N-modes3``: the same with 3 contact modes an object (``modes=3``);
- ``phac2``: PHAC-2's 60 objects, ``--folds`` folds of whole trials (each fold holds out
  2 of each object's 10 trials).

All candidates read the same samples scaled by ``RobustInputScaler`` (the methods scale their
own). It writes ``compare_known.json`` (the machine, the commit, each figure and its folds),
prints a Markdown table and draws ``compare_known.png``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

CANDIDATES = ("best", "prototypes", "prototypes-1mode", "lda", "nn1", "cosface")


def simulated(n: int, modes: int, seed: int):
    """(train dataset, held-out x, y) of the simulator, the last 2 trials held out."""
    from app.data.simulator import simulate_dataset

    ds = simulate_dataset(n, 10, seed=seed, modes=modes)
    held = (ds.trials % 10) >= 8
    return [(ds.subset(np.flatnonzero(~held)), ds.samples[held], ds.labels[held])]


def phac2_folds(folds: int, seed: int):
    """PHAC-2 split into ``folds`` folds of whole trials, each object's trials shuffled."""
    from app.data.phac2 import load_phac2
    from app.data.sources import default_phac2_path

    ds = load_phac2(default_phac2_path())
    rng = np.random.default_rng(seed)
    rank = np.empty(len(ds), np.int64)
    for c in range(ds.n_classes):
        rows = np.flatnonzero(ds.labels == c)
        rank[rows] = rng.permutation(len(rows))
    out = []
    for f in range(folds):
        held = (rank % folds) == f
        out.append((ds.subset(np.flatnonzero(~held)), ds.samples[held], ds.labels[held]))
    return out


def predict(candidate: str, train, x: np.ndarray, seed: int) -> np.ndarray:
    """Each held-out sample's predicted class index."""
    from app.framework.registry import make_method
    from app.framework.scaling import RobustInputScaler, flatten

    if candidate in ("best", "prototypes", "prototypes-1mode"):
        name = "best" if candidate == "best" else "prototypes"
        params = {"max_modes": 1} if candidate == "prototypes-1mode" else {}
        model = make_method(name, seed=seed, n_jobs=2, **params).fit(train)
        return model.known_proba(x).argmax(axis=1)
    scaler = RobustInputScaler().fit(flatten(train.samples))
    z, q = scaler.transform(flatten(train.samples)), scaler.transform(flatten(x))
    if candidate == "lda":
        from sklearn.discriminant_analysis import LinearDiscriminantAnalysis

        lda = LinearDiscriminantAnalysis(solver="lsqr", shrinkage="auto").fit(z, train.labels)
        return lda.predict(q)
    if candidate == "nn1":
        d2 = (q**2).sum(axis=1)[:, None] - 2.0 * q @ z.T + (z**2).sum(axis=1)[None]
        return train.labels[d2.argmin(axis=1)]
    if candidate == "cosface":
        return cosface_predict(z, train.labels, train.n_classes, q, seed)
    raise ValueError(f"unknown candidate {candidate!r}; choose from {', '.join(CANDIDATES)}")


def cosface_predict(
    z: np.ndarray, y: np.ndarray, n_classes: int, q: np.ndarray, seed: int
) -> np.ndarray:
    """The ``cosface`` candidate (module docstring)."""
    import torch
    from torch import nn

    torch.manual_seed(seed)
    net = nn.Sequential(nn.Linear(z.shape[1], 512), nn.ReLU(), nn.Linear(512, 128))
    weights = nn.Parameter(torch.randn(n_classes, 128) * 0.01)
    opt = torch.optim.Adam([*net.parameters(), weights], lr=1e-3, weight_decay=1e-4)
    xt, yt = torch.as_tensor(z, dtype=torch.float32), torch.as_tensor(y, dtype=torch.long)
    scale, margin = 16.0, 0.2
    gen = torch.Generator().manual_seed(seed)
    for _ in range(60):
        for idx in torch.randperm(len(xt), generator=gen).split(256):
            emb = nn.functional.normalize(net(xt[idx]), dim=1)
            cos = emb @ nn.functional.normalize(weights, dim=1).T
            logits = scale * (cos - margin * nn.functional.one_hot(yt[idx], n_classes))
            loss = nn.functional.cross_entropy(logits, yt[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
    with torch.no_grad():
        train_e = nn.functional.normalize(net(xt), dim=1).numpy()
        query_e = nn.functional.normalize(net(torch.as_tensor(q, dtype=torch.float32)), dim=1)
    protos = np.stack([train_e[y == c].mean(axis=0) for c in range(n_classes)])
    protos /= np.linalg.norm(protos, axis=1, keepdims=True)
    return (query_e.numpy() @ protos.T).argmax(axis=1)


def run(datasets: dict, candidates: list[str], seed: int) -> dict:
    out: dict = {}
    for name, splits in datasets.items():
        out[name] = {}
        for cand in candidates:
            accs, secs = [], []
            for train, x, y in splits:
                t = time.perf_counter()
                accs.append(float((predict(cand, train, x, seed) == y).mean()))
                secs.append(time.perf_counter() - t)
            out[name][cand] = {"acc": float(np.mean(accs)), "folds": accs, "s": sum(secs)}
            print(f"compare_known: {name} {cand} {np.mean(accs):.3f}", file=sys.stderr)
    return out


def table(results: dict, candidates: list[str]) -> str:
    lines = ["| data set | " + " | ".join(candidates) + " |"]
    lines.append("| --- |" + " --- |" * len(candidates))
    for name, row in results.items():
        cells = []
        for c in candidates:
            folds = row[c]["folds"]
            sd = f" ± {np.std(folds, ddof=1):.3f}" if len(folds) > 1 else ""
            cells.append(f"{row[c]['acc']:.3f}{sd}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(results: dict, candidates: list[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(results)
    fig, ax = plt.subplots(figsize=(1.6 + 1.4 * len(names), 4.8))
    width = 0.8 / len(candidates)
    for i, cand in enumerate(candidates):
        xs = np.arange(len(names)) + (i - (len(candidates) - 1) / 2) * width
        ax.bar(xs, [results[n][cand]["acc"] for n in names], width, label=cand)
    ax.set_xticks(np.arange(len(names)), names, rotation=20)
    ax.set_ylabel("known-object accuracy, held-out trials")
    ax.set_ylim(0, 1.02)
    ax.set_title("Candidate representations on the same splits")
    ax.legend(fontsize=8, ncol=len(candidates), loc="upper center", bbox_to_anchor=(0.5, -0.22))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default="300,1000", help="simulated object counts")
    p.add_argument("--folds", type=int, default=5, help="PHAC-2's trial folds (0: none)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--candidates", default=",".join(CANDIDATES))
    p.add_argument("--out", default="results/compare_known")
    args = p.parse_args(argv)
    try:
        args.sizes = [int(s) for s in args.sizes.split(",") if s.strip()]
    except ValueError:
        p.error(f"--sizes must be integers separated by commas, got {args.sizes!r}")
    if any(n < 2 for n in args.sizes):
        p.error("every size must be at least 2 objects")
    args.candidates = [c.strip() for c in args.candidates.split(",") if c.strip()]
    unknown = [c for c in args.candidates if c not in CANDIDATES]
    if unknown or not args.candidates:
        p.error(f"--candidates takes some of {', '.join(CANDIDATES)}, got {unknown or 'none'}")
    if args.folds == 1 or args.folds < 0:
        p.error("--folds must be 0 or at least 2")
    return args


def main(argv: list[str] | None = None) -> int:
    from bench.scale import machine

    args = parse(argv)
    datasets: dict = {}
    for n in args.sizes:
        datasets[f"sim-{n}"] = simulated(n, 1, args.seed)
        datasets[f"sim-{n}-modes3"] = simulated(n, 3, args.seed)
    if args.folds:
        datasets["phac2"] = phac2_folds(args.folds, args.seed)
    results = run(datasets, args.candidates, args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    report = {"machine": machine(), "seed": args.seed, "results": results}
    (out / "compare_known.json").write_text(json.dumps(report, indent=2))
    print(table(results, args.candidates))
    plot(results, args.candidates, out / "compare_known.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
