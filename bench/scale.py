"""Scale in objects: what a method costs, and how well it recognises, from 60 to 30,000
known objects of the built-in simulator, beside a shrinkage-LDA reference.

    .venv/bin/python -m bench.scale [--sizes 60,300,1000,3000,10000,30000] [--max N]
                                    [--novel 20] [--trials 10] [--seed 0]
                                    [--separation none|phac2] [--modes K]
                                    [--method NAME] [--no-reference]
                                    [--out results/scale/] [--param NAME=VALUE ...]

For each size N (up to ``--max``) a child process of its own (so each peak RSS is that
size's alone) simulates ``simulate_dataset(N + novel, trials, seed, separation, modes)``:
the first N objects are known, the last ``--novel`` are novel. ``--separation phac2`` keeps
the simulator's objects as far apart as PHAC-2's at every size (``bench/separation.py``
measures it); ``none``, the default, is the simulator as it is, whose objects crowd together
as N grows; ``--modes K`` gives each object K contact modes. Two whole trials per known
object are held out.
The child fits ``--method`` (the service's default method unless named; its defaults,
each ``--param`` in place of a default, its value read as JSON where it parses) on the rest
and measures. ``n_jobs`` is the method's default, 1, which the service's bootstrap and its
worker's refit run with; ``--param n_jobs=2`` measures a fit on more cores (each record
names its ``n_jobs``):

- ``fit_s`` and ``fit_peak_gb``: the fit's wall time and the process's peak RSS from the
  start of the fit, the kernel's high-water mark (VmHWM, reset before the fit; the dataset
  is in memory already; ``simulator_peak_gb`` is the mark before it), ``bundle_mb``;
  ``fit_timings``: the fitted model's own breakdown (``metrics["timings"]``: novelty
  tuning, known model, attributes, ``by_procedure_s`` for the per-procedure models, total),
  whose
  ``by_procedure_s`` is a column of the table;
- ``enrol_ms``: ``add_novel_classes`` of one class by attribute vector (median of up to 5:
  as many as novel vectors are free), and ``one_shot_ms``: ``add_one_shot`` of one sample
  to a zero-shot class (the same count), after one untimed one-shot (a model's first packs
  its forests for the walk, a cost once per model: 4.35 s at 10,000 objects,
  ``bench.scale_service --in-process-only``);
- ``promote_s``: ``with_known_samples`` of one novel object's samples, the promotion the
  service makes without a refit (median of 3), beside ``fit_s``, the refit it replaces;
- ``recognise_1_us``: ``recognize_batch`` of one sample (median of 300 different samples),
  ``batch_per_sample_us`` and ``throughput_per_s`` for batches of 1,024, and
  ``batch256_per_sample_us`` for batches of 256 (the median of 5 different ones);
- ``known_acc``: top-1 among the known objects on the held-out trials, beside ``nn1_acc``,
  a 1-nearest-neighbour classifier on the same scaled inputs (a reference that tells the
  method's loss from the simulator's objects crowding together), ``known_acc_one_procedure``:
  the same from one exploratory procedure alone (the others missing), the mean over the
  procedures (what the per-procedure models answer), and ``zsl_acc``: the
  novel objects' samples among the novel classes enrolled by their attribute vectors, and
  ``zsl_by_novel``: the same for the first 10, 100 and 1,000 novel objects (as many as
  ``--novel`` gives), with how many of them could be enrolled (a vector not yet taken);
- ``nd_auroc``: the method's novelty score, held-out known trials against the novel
  objects' samples, and ``nd_known_kept`` / ``nd_novel_detected`` at its threshold;
- ``lda_acc`` and ``lda_auroc`` (unless ``--no-reference``): scikit-learn's
  ``LinearDiscriminantAnalysis(solver="lsqr", shrinkage="auto")`` on the same scaled,
  flattened samples, its novelty score 1 - its largest posterior;
- ``vectors_distinct`` (distinct attribute vectors among the N known objects) and
  ``novel_vectors_taken`` (novel objects whose vector a known object has: the service
  answers such an enrolment with a 409).

It writes ``scale.json`` (one record per size, with the machine and the commit), prints a
Markdown table, and draws ``scale.png``: each cost against N on log-log axes, with its
fitted exponent (least-squares slope of log cost on log N) in the legend.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from app.cli.train import parse_params

COSTS = (
    "fit_s",
    "fit_peak_gb",
    "bundle_mb",
    "enrol_ms",
    "one_shot_ms",
    "promote_s",
    "recognise_1_us",
    "batch_per_sample_us",
    "batch256_per_sample_us",
)
BLOCK = 1024
SMALL_BLOCK = 256
NOVEL_COUNTS = (10, 100, 1000)  # zsl_by_novel: the first this many novel objects


def _peak_gb() -> float:
    """The process's peak resident memory since start or the last ``_reset_peak``: the
    kernel's high-water mark (VmHWM), not a sample."""
    with open("/proc/self/status") as f:
        return int(f.read().split("VmHWM:")[1].split()[0]) / 1e6


def _reset_peak() -> None:
    """Start the high-water mark again from the current resident memory (Linux's
    clear_refs 5)."""
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")


def measure(
    n: int,
    novel: int,
    trials: int,
    seed: int,
    separation: str = "none",
    params: dict | None = None,
    method: str = "best",
    modes: int = 1,
    reference: bool = True,
) -> dict:
    """Every figure of one size, in this process (``--one``); ``params``: ``method``'s
    hyper-parameters in place of its defaults; ``reference``: fit the shrinkage-LDA
    reference too."""
    from app.data.procedures import keep_only
    from app.data.simulator import simulate_dataset
    from app.framework import bundle
    from app.framework.registry import make_method
    from app.framework.scaling import RobustInputScaler, flatten

    ds = simulate_dataset(
        n + novel,
        trials,
        seed=seed,
        separation=None if separation == "none" else separation,
        modes=modes,
    )
    held = (ds.trials % trials) >= trials - 2
    known = ds.labels < n
    train = ds.subset(np.flatnonzero(known & ~held)).select_classes(np.arange(n))
    x_test, y_test = ds.samples[known & held], ds.labels[known & held]
    x_novel, y_novel = ds.samples[~known], ds.labels[~known] - n
    vectors = ds.class_attributes
    known_vectors = {tuple(v) for v in vectors[:n].astype(int).tolist()}
    del ds

    sim_peak = _peak_gb()
    _reset_peak()  # the kernel's high-water mark from here on is the fit's
    t = time.perf_counter()
    # "auto" returns the model of the method its probe chose
    model = make_method(method, **{"seed": seed, **(params or {})}).fit(train, progress=True)
    out: dict = {"objects": n, "separation": separation, "fit_s": time.perf_counter() - t}
    out["chosen_by"] = model.metrics.get("chosen_by")
    out["n_jobs"] = getattr(model, "n_jobs", None)
    out["method"], out["modes"] = method, modes
    out["params"] = params or {}
    out["fit_peak_gb"] = _peak_gb()
    out["simulator_peak_gb"] = sim_peak
    out["fit_timings"] = dict(model.metrics.get("timings", {}))
    out["by_procedure_s"] = out["fit_timings"].get("by_procedure_s")
    out["bundle_mb"] = len(bundle.to_bytes(model)) / 1e6

    novel_names = [f"novel-{i}" for i in range(novel)]
    out["novel_vectors_taken"] = sum(tuple(v) in known_vectors for v in vectors[n:].astype(int))
    out["vectors_distinct"] = len(known_vectors)
    free, seen = [], set(known_vectors)  # novel objects whose vector nobody has yet
    for i in range(novel):
        v = tuple(vectors[n + i].astype(int).tolist())
        if v not in seen:
            free.append(i)
            seen.add(v)
    enrol, shot = [], []
    if free:  # once, untimed: a model's first one-shot packs its forests for the walk
        i = free[0]
        warm = model.add_novel_classes([novel_names[i]], vectors[n + i : n + i + 1])
        warm.add_one_shot(novel_names[i], x_novel[y_novel == i][:1])
    for i in free[:5]:
        t = time.perf_counter()
        one = model.add_novel_classes([novel_names[i]], vectors[n + i : n + i + 1])
        enrol.append(time.perf_counter() - t)
        t = time.perf_counter()
        one.add_one_shot(novel_names[i], x_novel[y_novel == i][:1])
        shot.append(time.perf_counter() - t)
    out["enrol_ms"] = float(np.median(enrol)) * 1e3 if enrol else None
    out["one_shot_ms"] = float(np.median(shot)) * 1e3 if shot else None
    promote = []
    for i in free[:3]:
        t = time.perf_counter()
        model.with_known_samples(
            {novel_names[i]: x_novel[y_novel == i]}, {novel_names[i]: vectors[n + i]}
        )
        promote.append(time.perf_counter() - t)
    out["promote_s"] = float(np.median(promote)) if promote else None
    if free:
        with_novel = model.add_novel_classes(
            [novel_names[i] for i in free], vectors[n + np.array(free)]
        )
        rows = np.isin(y_novel, free)
        p = with_novel.novel_proba(x_novel[rows])
        out["zsl_acc"] = float((np.asarray(free)[p.argmax(axis=1)] == y_novel[rows]).mean())
    else:
        out["zsl_acc"] = None
    out["zsl_by_novel"] = {}
    for count in NOVEL_COUNTS:  # zero-shot as the novel objects grow in number
        chosen = [i for i in free if i < count]
        if count > novel or not chosen:
            continue
        many = model.add_novel_classes(
            [novel_names[i] for i in chosen], vectors[n + np.array(chosen)]
        )
        rows = np.isin(y_novel, chosen)
        p = many.novel_proba(x_novel[rows])
        out["zsl_by_novel"][str(count)] = {
            "enrolled": len(chosen),
            "zsl": float((np.asarray(chosen)[p.argmax(axis=1)] == y_novel[rows]).mean()),
        }

    out["known_acc"] = _known_accuracy(model, x_test, y_test)
    if model.answers_from_some_procedures:
        out["known_acc_one_procedure"] = float(
            np.mean(
                [
                    _known_accuracy(model, keep_only(x_test, model.procedures, [j]), y_test)
                    for j in range(len(model.procedures))
                ]
            )
        )
    out["nn1_acc"] = _nearest_neighbour_accuracy(
        RobustInputScaler().fit(flatten(train.samples)), train, x_test, y_test
    )
    out.update(_novelty_figures(model, x_test, x_novel))
    if reference:
        out.update(_lda_reference(train, x_test, y_test, x_novel))

    times = []
    for i in range(300):
        sample = x_test[(i * 7919) % len(x_test)][None]
        t = time.perf_counter()
        model.recognize_batch(sample)
        times.append(time.perf_counter() - t)
    out["recognise_1_us"] = float(np.median(times)) * 1e6
    batch = x_test[:BLOCK]
    model.recognize_batch(batch)
    t = time.perf_counter()
    model.recognize_batch(batch)
    per = (time.perf_counter() - t) / len(batch)
    out["batch_per_sample_us"], out["throughput_per_s"] = per * 1e6, 1.0 / per
    # a robot fleet's batch: the median of 5 different batches of SMALL_BLOCK
    times = []
    for i in range(5):
        rows = x_test[(np.arange(SMALL_BLOCK) + i * SMALL_BLOCK) % len(x_test)]
        t = time.perf_counter()
        model.recognize_batch(rows)
        times.append((time.perf_counter() - t) / SMALL_BLOCK)
    out["batch256_per_sample_us"] = float(np.median(times)) * 1e6
    return out


def _known_accuracy(model, x: np.ndarray, y: np.ndarray) -> float:
    """Top-1 of ``model.known_proba`` on samples ``x`` of known classes ``y``, ``BLOCK``
    samples at a time (a block's posteriors are BLOCK x K)."""
    correct = 0
    for lo in range(0, len(x), BLOCK):
        p = model.known_proba(x[lo : lo + BLOCK])
        correct += int((p.argmax(axis=1) == y[lo : lo + BLOCK]).sum())
    return correct / len(x)


def _novelty_figures(model, x_test: np.ndarray, x_novel: np.ndarray) -> dict:
    """The method's own novelty score on held-out known trials against the novel objects'
    samples: AUROC, and the shares kept known and detected at its threshold."""
    from sklearn.metrics import roc_auc_score

    known = np.concatenate(
        [model.novelty_score(x_test[lo : lo + BLOCK]) for lo in range(0, len(x_test), BLOCK)]
    )
    novel = model.novelty_score(x_novel)
    truth = np.r_[np.zeros(len(known)), np.ones(len(novel))]
    return {
        "nd_auroc": float(roc_auc_score(truth, np.r_[known, novel])),
        "nd_known_kept": float((known <= model.novelty_threshold).mean()),
        "nd_novel_detected": float((novel > model.novelty_threshold).mean()),
    }


def _lda_reference(train, x_test: np.ndarray, y_test: np.ndarray, x_novel: np.ndarray) -> dict:
    """scikit-learn's ``LinearDiscriminantAnalysis(solver="lsqr", shrinkage="auto")`` on the
    same scaled, flattened samples: its known accuracy, and its novelty AUROC scoring a
    sample by 1 - its largest posterior."""
    from sklearn.discriminant_analysis import LinearDiscriminantAnalysis
    from sklearn.metrics import roc_auc_score

    from app.framework.scaling import RobustInputScaler, flatten

    t = time.perf_counter()
    scaler = RobustInputScaler().fit(flatten(train.samples))
    lda = LinearDiscriminantAnalysis(solver="lsqr", shrinkage="auto")
    lda.fit(scaler.transform(flatten(train.samples)), train.labels)

    def proba(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        top, conf = [], []
        for lo in range(0, len(x), BLOCK):
            p = lda.predict_proba(scaler.transform(flatten(x[lo : lo + BLOCK])))
            top.append(p.argmax(axis=1))
            conf.append(p.max(axis=1))
        return np.concatenate(top), np.concatenate(conf)

    top, known = proba(x_test)
    _, novel = proba(x_novel)
    truth = np.r_[np.zeros(len(known)), np.ones(len(novel))]
    return {
        "lda_acc": float((lda.classes_[top] == y_test).mean()),
        "lda_auroc": float(roc_auc_score(truth, np.r_[1.0 - known, 1.0 - novel])),
        "lda_s": time.perf_counter() - t,
    }


def _nearest_neighbour_accuracy(scaler, train, x_test, y_test) -> float:
    """1-NN on the scaled inputs, blocked (memory linear in the samples)."""
    from app.framework.scaling import flatten

    ref = scaler.transform(flatten(train.samples)).astype(np.float32)
    ref_sq = (ref**2).sum(axis=1)
    q = scaler.transform(flatten(x_test)).astype(np.float32)
    correct = 0
    for lo in range(0, len(q), 256):
        block = q[lo : lo + 256]
        d2 = ref_sq[None, :] - 2.0 * block @ ref.T
        correct += int((train.labels[d2.argmin(axis=1)] == y_test[lo : lo + 256]).sum())
    return correct / len(q)


def exponents(records: list[dict]) -> dict[str, float | None]:
    """Per cost, the least-squares slope of log cost on log N (None below 2 sizes)."""
    out = {}
    for cost in COSTS:
        pts = [(r["objects"], r[cost]) for r in records if r.get(cost)]
        if len(pts) < 2:
            out[cost] = None
            continue
        n, c = np.log(np.array(pts, float)).T
        out[cost] = float(np.polyfit(n, c, 1)[0])
    return out


def markdown_rows(records: list[dict], cols: tuple[str, ...], digits: str) -> list[str]:
    """A Markdown table's header, rule and one row per record of ``cols``: floats in the
    format ``digits`` (e.g. ".3g"), a missing or None value as "–"."""
    lines = ["| " + " | ".join(cols) + " |", "|" + " --- |" * len(cols)]
    for r in records:
        cells = [
            "–"
            if r.get(c) is None
            else format(r[c], digits)
            if isinstance(r[c], float)
            else str(r[c])
            for c in cols
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def table(records: list[dict], slopes: dict) -> str:
    cols = ("objects", *COSTS, "by_procedure_s", "throughput_per_s", "known_acc", "nn1_acc")
    cols += ("lda_acc", "nd_auroc", "lda_auroc", "nd_known_kept", "nd_novel_detected")
    cols += ("known_acc_one_procedure",)
    cols += ("zsl_acc",)
    cols += ("vectors_distinct", "novel_vectors_taken")
    lines = markdown_rows(records, cols, ".3g")
    fitted = [f"{slopes[c]:.2f}" if slopes.get(c) is not None else "–" for c in COSTS]
    lines.append("| exponent | " + " | ".join(fitted) + " |" + " |" * (len(cols) - len(COSTS) - 1))
    return "\n".join(lines)


def plot(records: list[dict], slopes: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.5))
    for cost in COSTS:
        pts = [(r["objects"], r[cost]) for r in records if r.get(cost)]
        if pts:
            n, c = zip(*pts, strict=True)
            slope = slopes.get(cost)
            ax.loglog(n, c, "o-", label=f"{cost} (N^{slope:.2f})" if slope else cost)
    finish_plot(
        fig,
        path,
        "known objects N",
        "cost (units in the name)",
        f"{records[0].get('method', 'best')} on the simulator: cost against the number of "
        "known objects",
        legend_size=8,
    )


def finish_plot(fig, path, xlabel: str, ylabel: str, title: str, legend_size: int) -> None:
    """Label the figure's one log-scale plot (grid on both scales, legend), write it to
    ``path`` as a PNG and close it: the benches' plots against the number of objects."""
    import matplotlib.pyplot as plt

    ax = fig.axes[0]
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=legend_size)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def machine() -> dict:
    """The machine and the code a result comes from, which every bench's JSON records:
    ``commit`` is HEAD, and ``dirty`` says whether tracked files differed from it
    (``changed`` lists them). The documents cite no result with ``dirty`` true
    (``tests/test_docs_figures.py``): its code is in no commit."""

    def git(*args: str) -> str:
        return subprocess.run(["git", *args], capture_output=True, text=True).stdout

    # unstripped: a porcelain line's status columns may begin with a space (" M path")
    changed = git("status", "--porcelain", "--untracked-files=no").splitlines()
    pages = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    return {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "memory_gb": round(pages / 1e9, 1),
        "python": platform.python_version(),
        "commit": git("rev-parse", "--short", "HEAD").strip(),
        "dirty": bool(changed),
        "changed": [line[3:] for line in changed],
    }


def parse_sizes(p: argparse.ArgumentParser, text: str) -> list[int]:
    """``--sizes``: distinct integers, at least 2 each, smallest first (else ``p.error``)."""
    try:
        sizes = sorted({int(s) for s in text.split(",") if s.strip()})
    except ValueError:
        p.error(f"--sizes must be integers separated by commas, got {text!r}")
    if not sizes or sizes[0] < 2:
        p.error("every size must be at least 2 objects")
    return sizes


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default="60,300,1000,3000,10000,30000")
    p.add_argument("--max", type=int, default=None, help="stop after this size")
    p.add_argument("--novel", type=int, default=20)
    p.add_argument("--trials", type=int, default=10)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--separation",
        default="none",
        help="none (the simulator as it is) or phac2 (objects as far apart as PHAC-2's)",
    )
    p.add_argument("--method", default=None, help="the method to fit (default: the service's)")
    p.add_argument("--modes", type=int, default=1, help="contact modes of each object")
    p.add_argument(
        "--no-reference", action="store_true", help="leave out the shrinkage-LDA reference"
    )
    p.add_argument("--out", default="results/scale")
    p.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a hyper-parameter of the method in place of its default (repeatable), "
        "e.g. --param procedure_estimators=100",
    )
    p.add_argument("--one", type=int, help=argparse.SUPPRESS)  # a child's own size
    args = p.parse_args(argv)
    args.sizes = parse_sizes(p, args.sizes)
    try:
        args.params = parse_params(args.param)
    except ValueError as exc:
        p.error(str(exc))
    if args.max is not None:
        if args.max < args.sizes[0]:
            p.error(f"--max {args.max} is below the smallest size {args.sizes[0]}")
        args.sizes = [s for s in args.sizes if s <= args.max]
    from app.data.simulator import SEPARATIONS

    if args.separation != "none" and args.separation not in SEPARATIONS:
        p.error(f"--separation takes none or {', '.join(SEPARATIONS)}, got {args.separation!r}")
    from app.framework.registry import DEFAULT_METHOD, METHODS

    args.method = args.method or DEFAULT_METHOD
    if args.method not in METHODS:
        p.error(f"--method takes one of {', '.join(sorted(METHODS))}, got {args.method!r}")
    if args.modes < 1:
        p.error(f"--modes must be at least 1, got {args.modes}")
    if args.novel < 1 or args.trials < 4:
        p.error("--novel must be at least 1 and --trials at least 4 (2 are held out)")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    if args.one is not None:
        record = measure(
            args.one,
            args.novel,
            args.trials,
            args.seed,
            args.separation,
            args.params,
            args.method,
            args.modes,
            not args.no_reference,
        )
        print(json.dumps(record))
        return 0
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    records = []
    for n in args.sizes:
        print(f"scale: {n} known objects ...", file=sys.stderr, flush=True)
        cmd = [sys.executable, "-m", "bench.scale", "--one", str(n)]
        cmd += ["--novel", str(args.novel), "--trials", str(args.trials), "--seed", str(args.seed)]
        cmd += ["--separation", args.separation, "--method", args.method]
        cmd += ["--modes", str(args.modes)] + (["--no-reference"] if args.no_reference else [])
        cmd += [f"--param={item}" for item in args.param]
        done = subprocess.run(cmd, stdout=subprocess.PIPE, text=True)
        if done.returncode != 0:
            print(f"scale: {n} objects failed (exit {done.returncode})", file=sys.stderr)
            break
        records.append(json.loads(done.stdout.strip().splitlines()[-1]))
        slopes = exponents(records)
        report = {
            "machine": machine(),
            "seed": args.seed,
            "novel": args.novel,
            "trials": args.trials,
            "separation": args.separation,
            "method": args.method,
            "modes": args.modes,
            "params": args.params,
            "sizes": records,
            "exponents": slopes,
        }
        (out / "scale.json").write_text(json.dumps(report, indent=2))
    if not records:
        return 1
    print(table(records, slopes))
    plot(records, slopes, out / "scale.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
