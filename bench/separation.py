"""How distinguishable objects are: real PHAC-2 beside the built-in simulator, 60 to 30,000
objects, with and without the simulator's ``separation`` option.

    .venv/bin/python -m bench.separation [--sizes 60,300,1000,3000,30000]
                                         [--separations none,phac2] [--trials 10] [--seed 0]
                                         [--nn1-max 3000] [--phac2 ../shared/data/phac2]
                                         [--out results/separation/]

The space: every feature through the project's ``RobustInputScaler`` (what ``best`` and
``bench.scale``'s 1-NN reference see), then divided by its pooled within-object standard
deviation, so a distance counts in units of trial-to-trial spread whatever a feature's
range. (Plain robust scaling would weigh PHAC-2's many noisy features like its few clean
ones: there 1-NN on held-out trials is 0.44 against 0.94 after this division, and `best`'s
known accuracy is 0.98.)

The statistic, per object k with n_k trials and mean m_k: ``sep_k = D_k / a_k``. D_k^2 is
the smallest, over the other objects j, of ||m_k - m_j||^2 - s_k^2 / n_k - s_j^2 / n_j
(s^2: the unbiased trace of an object's trial covariance; subtracting it removes what the
means' own noise adds on average; 0 where the difference is negative). a_k is the standard
deviation of k's trials along the line from m_k to that nearest mean: a trial lands nearer
the wrong one of the two means about Phi(-sep_k / 2) of the time, whatever the number of
features, so the figure compares spaces of 188 and 960 features. (``trace_median``, the
same distance over the whole spread s_k, does not: it falls with the number of features.)
It needs only the objects' means and spreads, so it is cheap at 30,000 objects. Reported:
its median and quartiles over objects and the 10th percentile (the most crowded objects),
a histogram, and, for up to ``--nn1-max`` objects, ``nn1``: leave-one-trial-out
1-nearest-neighbour accuracy over whole trials in the same space, and ``nn1_scaled`` the
same after robust scaling alone.

PHAC-2 (``--phac2``: 60 objects, 10 trials, 188 static features) is measured once; the
simulator at each size and ``--separations`` value (``none``: today's default) with
``simulate_dataset(N, trials, seed, separation=...)``. It writes ``separation.json``,
prints a Markdown table and draws ``separation.png`` (the statistic against N).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from bench.scale import finish_plot, markdown_rows, parse_sizes

BLOCK = 1024
SCALER_ROWS = 50_000  # the scaler's medians and quartiles from at most this many trials


def statistic(samples: np.ndarray, labels: np.ndarray, nn1: bool = True, seed: int = 0) -> dict:
    """The separation statistic (and, if ``nn1``, the 1-NN accuracies) of one dataset."""
    from app.framework.scaling import RobustInputScaler, flatten

    labels = np.asarray(labels)
    rng = np.random.default_rng(seed)
    rows = np.arange(len(samples))
    fit_rows = rows if len(rows) <= SCALER_ROWS else np.sort(rng.choice(rows, SCALER_ROWS, False))
    scaler = RobustInputScaler().fit(flatten(samples[fit_rows]))
    classes, labels = np.unique(labels, return_inverse=True)
    k, order = len(classes), np.argsort(labels, kind="stable")
    counts = np.bincount(labels, minlength=k)
    if counts.min() < 2:
        raise ValueError("every object needs at least 2 trials")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    dim = flatten(samples[:1]).shape[1]
    means = np.empty((k, dim), np.float64)
    within = np.empty((k, dim), np.float32)  # per object and feature: sum of squared deviations
    for lo in range(0, k, 512):  # objects in groups, their trials contiguous in ``order``
        hi = min(k, lo + 512)
        idx = order[starts[lo] : starts[hi - 1] + counts[hi - 1]]
        z = scaler.transform(flatten(samples[idx])).astype(np.float64)
        seg = starts[lo:hi] - starts[lo]
        sums = np.add.reduceat(z, seg, axis=0)
        means[lo:hi] = sums / counts[lo:hi, None]
        within[lo:hi] = np.add.reduceat(z**2, seg, axis=0) - sums * means[lo:hi]
    pooled = np.maximum(within.sum(axis=0, dtype=np.float64) / (len(labels) - k), 1e-12)
    unit = 1.0 / np.sqrt(pooled)
    spread2 = (np.maximum(within, 0) @ (1.0 / pooled)) / (counts - 1)  # s_k^2, unbiased trace
    m = (means * unit).astype(np.float32)
    sq = (m.astype(np.float64) ** 2).sum(axis=1)
    noise = spread2 / counts  # what each mean's own noise adds to a squared distance
    nearest, partner = np.empty(k), np.empty(k, np.int64)
    for lo in range(0, k, BLOCK):
        hi = min(k, lo + BLOCK)
        d2 = sq[lo:hi, None] + sq[None, :] - 2.0 * (m[lo:hi] @ m.T).astype(np.float64)
        d2 -= noise[lo:hi, None] + noise[None, :]
        d2[np.arange(hi - lo), np.arange(lo, hi)] = np.inf
        partner[lo:hi] = d2.argmin(axis=1)
        nearest[lo:hi] = d2[np.arange(hi - lo), partner[lo:hi]]
    # trial spread along the line to the nearest object: what a nearest-mean rule must beat
    u = m - m[partner]
    u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-12)
    along = np.empty(k)
    for lo in range(0, k, 512):
        hi = min(k, lo + 512)
        idx = order[starts[lo] : starts[hi - 1] + counts[hi - 1]]
        z = scaler.transform(flatten(samples[idx])) * unit.astype(np.float32)
        own = np.repeat(np.arange(lo, hi), counts[lo:hi])
        proj = ((z - m[own]) * u[own]).sum(axis=1)
        along[lo:hi] = np.bincount(own - lo, weights=proj**2, minlength=hi - lo)
    along /= counts - 1
    sep = np.sqrt(np.maximum(nearest, 0.0) / along)
    trace = np.sqrt(np.maximum(nearest, 0.0) / spread2)
    q10, q25, q50, q75 = np.percentile(sep, [10, 25, 50, 75])
    out = {
        "objects": int(k),
        "trials": int(len(labels)),
        "features": int(dim),
        "sep_median": float(q50),
        "sep_q10": float(q10),
        "sep_q25": float(q25),
        "sep_q75": float(q75),
        "sep_hist": np.histogram(sep, bins=30, range=(0.0, 15.0))[0].tolist(),
        "trace_median": float(np.median(trace)),
    }
    if nn1:
        z = scaler.transform(flatten(samples))
        out["nn1_scaled"] = _loo_nn1(z, labels)
        z *= unit.astype(np.float32)
        out["nn1"] = _loo_nn1(z, labels)
    return out


def _loo_nn1(z: np.ndarray, labels: np.ndarray) -> float:
    """Leave-one-trial-out 1-NN accuracy: each trial's nearest other trial, blocked."""
    sq = (z.astype(np.float64) ** 2).sum(axis=1).astype(np.float32)
    correct = 0
    for lo in range(0, len(z), BLOCK):
        hi = min(len(z), lo + BLOCK)
        d2 = sq[None, :] - 2.0 * (z[lo:hi] @ z.T)  # + |z_i|^2, the same along a row
        d2[np.arange(hi - lo), np.arange(lo, hi)] = np.inf
        correct += int((labels[d2.argmin(axis=1)] == labels[lo:hi]).sum())
    return correct / len(z)


def table(records: list[dict]) -> str:
    cols = ("data", "separation", "objects", "sep_median", "sep_q10", "sep_q25", "sep_q75")
    cols += ("nn1", "nn1_scaled")
    return "\n".join(markdown_rows(records, cols, ".3f"))


def plot(records: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5))
    real = [r for r in records if r["data"] == "phac2"]
    for r in real:
        ax.axhspan(r["sep_q25"], r["sep_q75"], color="k", alpha=0.08, label="PHAC-2 quartiles")
        ax.axhline(r["sep_median"], color="k", ls="--", label="PHAC-2 median (60 objects)")
        ax.plot([r["objects"]], [r["sep_q10"]], "kv", label="PHAC-2 10th percentile")
    for name, colour in (("none", "tab:red"), ("phac2", "tab:blue")):
        sim = [r for r in records if r["data"] == "simulator" and r["separation"] == name]
        if not sim:
            continue
        n = [r["objects"] for r in sim]
        label = "simulator, default" if name == "none" else f"simulator, separation={name!r}"
        ax.fill_between(n, [r["sep_q25"] for r in sim], [r["sep_q75"] for r in sim],
                        color=colour, alpha=0.15)  # fmt: skip
        ax.plot(n, [r["sep_median"] for r in sim], "o-", color=colour, label=label + ", median")
        ax.plot(n, [r["sep_q10"] for r in sim], "v:", color=colour, label=label + ", 10th pct")
    ax.set_xscale("log")
    finish_plot(
        fig,
        path,
        "objects N",
        "nearest other object's mean / trial spread along that line",
        "How far the nearest other object is (bench/separation.py)",
        legend_size=7,
    )


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default="60,300,1000,3000,30000")
    p.add_argument("--separations", default="none,phac2")
    p.add_argument("--trials", type=int, default=10)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--nn1-max", type=int, default=3000, help="1-NN only up to this many objects")
    p.add_argument("--phac2", default="../shared/data/phac2", help="'' leaves PHAC-2 out")
    p.add_argument("--out", default="results/separation")
    args = p.parse_args(argv)
    from app.data.simulator import SEPARATIONS

    args.sizes = parse_sizes(p, args.sizes)
    args.separations = [s.strip() for s in args.separations.split(",") if s.strip()]
    bad = [s for s in args.separations if s != "none" and s not in SEPARATIONS]
    if bad or not args.separations:
        p.error(f"--separations takes none and {', '.join(SEPARATIONS)}, got {bad}")
    if args.trials < 2:
        p.error("--trials must be at least 2")
    return args


def main(argv: list[str] | None = None) -> int:
    from app.data.simulator import simulate_dataset
    from bench.scale import machine

    args = parse(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    records = []
    if args.phac2:
        from app.data.phac2 import load_phac2

        real = load_phac2(args.phac2)
        stat = statistic(real.samples, real.labels)
        records.append({"data": "phac2", "separation": None, **stat})
    for name in args.separations:
        for n in args.sizes:
            print(f"separation: simulator {name}, {n} objects ...", file=sys.stderr, flush=True)
            ds = simulate_dataset(
                n, args.trials, seed=args.seed, separation=None if name == "none" else name
            )
            stat = statistic(ds.samples, ds.labels, nn1=n <= args.nn1_max, seed=args.seed)
            del ds
            records.append({"data": "simulator", "separation": name, **stat})
            report = {"machine": machine(), "args": vars(args), "records": records}
            (out / "separation.json").write_text(json.dumps(report, indent=2))
    print(table(records))
    plot(records, out / "separation.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
