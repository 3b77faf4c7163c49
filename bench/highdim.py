"""The default method on a sensor of many values a touch, side by side with extra-trees.

    .venv/bin/python -m bench.highdim [--objects 60] [--trials 6] [--channels 200]
                                      [--steps 50] [--seeds 1,2,3]
                                      [--out docs/results/highdim/]

A GelSight-like set: ``simulate_dataset(objects, trials, channels=C, steps=T)`` (C x T values
a touch, neighbouring taxels correlated; ``app.data.simulator``), one whole trial of each
object held out (trial ``seed % trials``), the rest the training set: 60 objects x 5 trials
= 300 touches of 10,000 values at the defaults. For each seed the default method
(``make_method("auto")``, which probes ``prototypes`` and ``best`` and fits the winner) and
the extra-trees baseline (``make_method("extratrees")``, its defaults: 300 trees on every
core) are fitted on the same touches, each in a fresh process of its own, one after the
other, and measured there:

- ``fit_s``: wall seconds of ``fit``; ``cpu_s``: the process's CPU seconds in it (every
  thread); their ratio shows how much of the machine a fit had;
- ``peak_rss_gb``: the process's high-water mark of resident memory (Linux ``VmHWM``) after
  the fit: Python, the libraries, the data set and the fit together; ``rss_before_gb``:
  its resident memory just before ``fit``;
- ``known_acc``: known-object accuracy on the held-out trials;
- ``chosen``, ``probe_s``: the method ``auto`` chose and its probe's seconds (of ``fit_s``);
  ``reduced_dims``, ``modes``: the components ``prototypes`` kept and its modes a class.

A first, unrecorded fit of each method on a small set compiles the numba kernels (kept in
``__pycache__``), so no recorded fit pays for compiling. It writes ``highdim.json`` (the
machine, ``lscpu``'s model name, the settings, every run and the means) and ``highdim.png``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import numpy as np

METHODS = ("auto", "extratrees")


def _status_gb(key: str) -> float:
    """``VmRSS`` or ``VmHWM`` of this process, in GB (Linux)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1]) / 1e6
    raise KeyError(key)


def split(objects: int, trials: int, channels: int, steps: int, seed: int):
    """(training set, held-out samples, their labels): trial ``seed % trials`` of each object
    held out, whole."""
    from app.data.simulator import simulate_dataset

    ds = simulate_dataset(objects, trials, seed=seed, channels=channels, steps=steps)
    held = (ds.trials % trials) == seed % trials
    return ds.subset(np.flatnonzero(~held)), ds.samples[held], ds.labels[held]


def fit_once(method: str, objects: int, trials: int, channels: int, steps: int, seed: int):
    """One measured fit (run in a fresh process: its memory is this fit's alone)."""
    from app.framework.registry import make_method

    train, x, y = split(objects, trials, channels, steps, seed)
    model = make_method(method, seed=seed)
    before = _status_gb("VmRSS")
    t, cpu = time.perf_counter(), time.process_time()
    model = model.fit(train)
    fit_s, cpu_s = time.perf_counter() - t, time.process_time() - cpu
    peak = _status_gb("VmHWM")
    acc = float(np.mean(model.known_proba(x).argmax(axis=1) == y))
    metrics = model.metrics
    chosen = metrics.get("chosen_by", {}).get("method")
    return {
        "method": method,
        "seed": seed,
        "n_train": len(train),
        "n_features": int(np.prod(train.input_shape)),
        "fit_s": round(fit_s, 2),
        "cpu_s": round(cpu_s, 2),
        "rss_before_gb": round(before, 3),
        "peak_rss_gb": round(peak, 3),
        "known_acc": acc,
        "chosen": chosen,
        "probe_s": metrics.get("chosen_by", {}).get("probe_seconds"),
        "reduced_dims": metrics.get("reduced_dims"),
        "modes": metrics.get("modes"),
    }


def in_child(*args):
    """``fit_once`` in a fresh spawned process."""
    with ProcessPoolExecutor(1, mp_context=get_context("spawn")) as pool:
        return pool.submit(fit_once, *args).result()


def cpu_model() -> str:
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True).stdout
    except OSError:
        return ""
    for line in out.splitlines():
        if line.startswith("Model name:"):
            return line.split(":", 1)[1].strip()
    return ""


def summary(runs: list[dict]) -> dict:
    out = {}
    for method in METHODS:
        mine = [r for r in runs if r["method"] == method]
        out[method] = {
            "fit_s_mean": round(float(np.mean([r["fit_s"] for r in mine])), 2),
            "fit_s_max": round(float(np.max([r["fit_s"] for r in mine])), 2),
            "cpu_s_mean": round(float(np.mean([r["cpu_s"] for r in mine])), 2),
            "peak_rss_gb_max": round(float(np.max([r["peak_rss_gb"] for r in mine])), 3),
            "known_acc_mean": round(float(np.mean([r["known_acc"] for r in mine])), 4),
            "known_acc_min": round(float(np.min([r["known_acc"] for r in mine])), 4),
        }
    a, e = out["auto"], out["extratrees"]
    out["auto_over_extratrees"] = {
        "fit_s": round(a["fit_s_mean"] / e["fit_s_mean"], 2),
        "cpu_s": round(a["cpu_s_mean"] / e["cpu_s_mean"], 2),
        "known_acc": round(a["known_acc_mean"] - e["known_acc_mean"], 4),
    }
    return out


def plot(report: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs, seeds = report["runs"], report["settings"]["seeds"]
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    width = 0.38
    for i, method in enumerate(METHODS):
        mine = {r["seed"]: r for r in runs if r["method"] == method}
        at = np.arange(len(seeds)) + (i - 0.5) * width
        for ax, key in zip(axes, ("fit_s", "peak_rss_gb", "known_acc"), strict=True):
            ax.bar(at, [mine[s][key] for s in seeds], width, label=method)
    titles = ("fit, wall seconds", "peak resident memory, GB", "known accuracy, held-out trials")
    for ax, title in zip(axes, titles, strict=True):
        ax.set_xticks(np.arange(len(seeds)), [f"seed {s}" for s in seeds])
        ax.set_title(title, fontsize=10)
    axes[0].axhline(60, color="grey", lw=0.8, ls="--")
    axes[1].axhline(2, color="grey", lw=0.8, ls="--")
    axes[2].set_ylim(0, 1)
    axes[0].legend(fontsize=8)
    s = report["settings"]
    fig.suptitle(
        f"{s['objects']} objects x {s['trials'] - 1} training trials, "
        f"{s['channels']} x {s['steps']} values a touch ({report['machine']['cpu_model']}, "
        f"{report['machine']['cpus']} CPUs)",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--objects", type=int, default=60)
    p.add_argument("--trials", type=int, default=6, help="per object, one of them held out")
    p.add_argument("--channels", type=int, default=200, help="a multiple of 4")
    p.add_argument("--steps", type=int, default=50)
    p.add_argument("--seeds", default="1,2,3")
    p.add_argument("--out", type=Path, default=Path("docs/results/highdim"))
    args = p.parse_args(argv)
    try:
        args.seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    except ValueError:
        p.error(f"--seeds must be integers joined by commas, got {args.seeds!r}")
    if not args.seeds:
        p.error("--seeds names no seed")
    if args.objects < 3 or args.trials < 3:
        p.error("--objects and --trials must be at least 3")
    if args.channels < 4 or args.channels % 4 or args.steps < 2:
        p.error("--channels must be a positive multiple of 4 and --steps at least 2")
    return args


def main(argv: list[str] | None = None) -> int:
    from bench.scale import machine

    args = parse(argv)
    shape = (args.objects, args.trials, args.channels, args.steps)
    for method in METHODS:  # compiles the numba kernels; not recorded
        in_child(method, 8, 3, 8, 6, 0)
    runs = []
    for seed in args.seeds:
        for method in METHODS:
            run = in_child(method, *shape, seed)
            runs.append(run)
            print(json.dumps(run), flush=True)
    report = {
        "machine": {**machine(), "cpu_model": cpu_model()},
        "settings": {
            "objects": args.objects,
            "trials": args.trials,
            "channels": args.channels,
            "steps": args.steps,
            "seeds": args.seeds,
        },
        "runs": runs,
        "summary": summary(runs),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "highdim.json").write_text(json.dumps(report, indent=1) + "\n")
    plot(report, args.out / "highdim.png")
    print(json.dumps(report["summary"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
