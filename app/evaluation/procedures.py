"""Figures against the exploratory procedures used, on the splits of ``protocol.evaluate``.

A robot that answers after fewer procedures saves their time. For every non-empty subset
S of the dataset's procedures (``TactileDataset.procedures``), the test samples with only
S kept (the others missing, ``app.data.procedures.keep_only``) give the split's figures
under ``procs{bits}_``, bits in procedure order (``procs1000_known_acc``: the first
procedure alone): ``known_acc``, ``nd_known_kept``, ``nd_novel_detected``, ``zsl`` and the
mixed known + novel ``gzsl_seen`` / ``_unseen`` / ``_h``, from the model with the split's
novel objects enrolled by attributes. A fixed order of procedures is the sequence of its
prefixes, so every order's curve is read from these.

**The adaptive rule**, for each target confidence t: every test sample (known and novel
mixed) starts with the model's ``first_procedure``; while its answer's probability is
below t and a procedure is left, it adds the answer's ``next_procedure``. Its figures
(``adaptive{t}_``, t in percent) are those of each sample's last answer, and
``adaptive{t}_time`` is the mean share of the whole exploration's robot time it used
(``_time_known`` / ``_time_novel`` for the known / novel samples), with each procedure's
duration from ``durations``.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from app.data.procedures import SECONDS, keep_only
from app.evaluation import metrics, plots
from app.framework.recognizer import TactileRecognizer

PER_SUBSET: tuple[str, ...] = metrics.MIXED_FIGURES
PER_ADAPTIVE: tuple[str, ...] = (
    *PER_SUBSET,
    "time",
    "time_known",
    "time_novel",
    "procedures",
)
#: target confidences of the adaptive rule that ``evaluate --procedures`` measures
TARGETS: tuple[float, ...] = (0.3, 0.4, 0.5, 0.7, 0.9, 0.99)

#: seconds of robot time per procedure, by name: ``app.data.procedures.SECONDS`` (its
#: comment gives each figure's source), which the model's next-procedure rule also uses
DURATIONS: dict[str, float] = SECONDS


def subsets(n: int) -> list[tuple[int, ...]]:
    """Every non-empty subset of ``n`` procedures, as sorted index tuples, smallest first."""
    return [c for r in range(1, n + 1) for c in itertools.combinations(range(n), r)]


def bits(subset: Sequence[int], n: int) -> str:
    return "".join("1" if j in subset else "0" for j in range(n))


def target_key(t: float) -> str:
    return f"adaptive{round(t * 100):d}"


def procedure_figures(n_procedures: int, targets: Sequence[float] = TARGETS) -> tuple[str, ...]:
    """The figures ``measure`` adds for ``n_procedures`` procedures (none for fewer than 2)."""
    if n_procedures < 2:
        return ()
    out = [f"procs{bits(s, n_procedures)}_{f}" for s in subsets(n_procedures) for f in PER_SUBSET]
    out += [f"{target_key(t)}_{f}" for t in targets for f in PER_ADAPTIVE]
    return tuple(out)


def check_durations(procedures: Sequence[str], durations: Mapping[str, float]) -> np.ndarray:
    """(P,) seconds of each procedure; ValueError naming one without a positive duration."""
    out = []
    for name in procedures:
        value = durations.get(name, DURATIONS.get(name))
        if value is None or not np.isfinite(value) or value <= 0:
            raise ValueError(
                f"procedure {name!r} has no positive duration; give one with "
                f"--durations {name}=SECONDS"
            )
        out.append(float(value))
    return np.array(out)


def measure(
    model: TactileRecognizer,
    known: tuple[np.ndarray, np.ndarray],
    novel: tuple[np.ndarray, np.ndarray],
    known_names: Sequence[str],
    novel_names: Sequence[str],
    durations: np.ndarray,
    targets: Sequence[float] = TARGETS,
) -> dict[str, float]:
    """The figures of ``procedure_figures`` for one split. ``model`` has the split's novel
    objects enrolled; ``known`` / ``novel``: (samples, class index) of the test samples."""
    (xk, yk), (xn, yn) = known, novel
    x = np.concatenate([xk, xn])
    is_known = np.r_[np.ones(len(xk), bool), np.zeros(len(xn), bool)]

    def figures(used: np.ndarray, prefix: str) -> dict[str, float]:
        return _figures(model, x, used, is_known, yk, yn, known_names, novel_names, prefix)

    return _sweep(model, x, None, len(x), figures, durations, targets, is_known)


def _sweep(
    model: TactileRecognizer,
    x: np.ndarray,
    groups: np.ndarray | None,
    n_answers: int,
    figures: Callable[[np.ndarray, str], dict[str, float]],
    durations: np.ndarray,
    targets: Sequence[float],
    is_known: np.ndarray | None = None,
) -> dict[str, float]:
    """``figures(used, prefix)`` of the ``n_answers`` answers for every subset of the
    procedures and for the adaptive rule at every target, with the rule's share of robot
    time (for the known and novel answers apart where ``is_known`` says which) and its
    number of procedures."""
    n = len(model.procedures)
    out: dict[str, float] = {}
    for subset in subsets(n):
        used = np.zeros((n_answers, n), bool)
        used[:, list(subset)] = True
        out.update(figures(used, f"procs{bits(subset, n)}_"))
    for t in targets:
        used = explore(model, x, t, groups)
        prefix = f"{target_key(t)}_"
        out.update(figures(used, prefix))
        share = used @ durations / durations.sum()
        out[prefix + "time"] = float(share.mean())
        if is_known is not None:
            out[prefix + "time_known"] = float(share[is_known].mean())
            out[prefix + "time_novel"] = float(share[~is_known].mean())
        out[prefix + "procedures"] = float(used.sum(axis=1).mean())
    return out


def explore(
    model: TactileRecognizer, x: np.ndarray, target: float, groups: np.ndarray | None = None
) -> np.ndarray:
    """(N, P) bool: the procedures the adaptive rule uses on each complete sample of ``x``:
    the model's first procedure, then each answer's next one until there is none. With
    ``groups`` ((N,) 0 … G-1: the fingers of one trial), (G, P): one answer per group, from
    its samples fused, as ``recognize_batch`` answers groups."""
    names = model.procedures
    g = np.arange(len(x)) if groups is None else np.asarray(groups, np.int64)
    used = np.zeros((int(g.max()) + 1, len(names)), bool)
    used[:, names.index(model.first_procedure)] = True
    active = np.arange(len(used))
    while len(active):
        rows = np.flatnonzero(np.isin(g, active))
        local = np.searchsorted(active, g[rows])  # active stays sorted
        partial = masked(x[rows], used[active][local])
        nxt = model.recognize_batch(
            partial,
            top_k=1,
            groups=None if groups is None else local,
            target_confidence=target,
        ).next_procedure
        go = nxt >= 0
        used[active[go], nxt[go]] = True
        active = active[go]
    return used


#: the figures ``measure_known`` gives for every subset and target
PER_SUBSET_KNOWN: tuple[str, ...] = ("known_acc", "nd_known_kept")


def procedure_figures_known(
    n_procedures: int, targets: Sequence[float] = TARGETS
) -> tuple[str, ...]:
    """The names of ``measure_known``'s figures."""
    out = [
        f"procs{bits(s, n_procedures)}_{f}" for s in subsets(n_procedures) for f in PER_SUBSET_KNOWN
    ]
    for t in targets:
        out += [f"{target_key(t)}_{f}" for f in (*PER_SUBSET_KNOWN, "time", "procedures")]
    return tuple(out)


def measure_known(
    model: TactileRecognizer,
    x: np.ndarray,
    y: np.ndarray,
    groups: np.ndarray,
    durations: np.ndarray,
    targets: Sequence[float] = TARGETS,
) -> dict[str, float]:
    """``measure`` for known objects only (raw trials: no attributes, no novel objects):
    ``x`` the test samples, ``groups`` the trial of each ((N,) 0 … G-1), ``y`` (G,) each
    trial's class. Per subset and target: ``known_acc`` (trials named right, their samples
    fused) and ``nd_known_kept`` (trials the model calls known); per target also ``time``
    and ``procedures``."""
    y = np.asarray(y)
    g = np.asarray(groups, np.int64)

    def figures(used: np.ndarray, prefix: str) -> dict[str, float]:
        answers = model.recognize_batch(masked(x, used[g]), top_k=1, groups=g)
        return {
            prefix + "known_acc": float(np.mean(answers.top_index[:, 0] == y)),
            prefix + "nd_known_kept": float(np.mean(~answers.is_novel)),
        }

    return _sweep(model, x, g, len(y), figures, durations, targets)


def masked(x: np.ndarray, used: np.ndarray) -> np.ndarray:
    """A float32 copy of complete samples ``x`` with the procedures ``used`` ((N, P) bool)
    does not mark made missing (NaN), as a robot that stopped there would send them."""
    out = np.array(x, np.float32, copy=True)
    for pattern in np.unique(used, axis=0):
        rows = (used == pattern).all(axis=1)
        out[rows] = keep_only(x[rows], range(len(pattern)), np.flatnonzero(pattern).tolist())
    return out


def _figures(model, x, used, is_known, yk, yn, known_names, novel_names, prefix):
    xm = masked(x, used)
    xk, xn = xm[is_known], xm[~is_known]
    threshold = model.novelty_threshold
    out = {
        "known_acc": metrics.argmax_accuracy(model.known_proba(xk), yk),
        "nd_known_kept": float(np.mean(model.novelty_score(xk) <= threshold)),
        "nd_novel_detected": metrics.detection_rate(model.novelty_score(xn), threshold),
        "zsl": metrics.argmax_accuracy(model.novel_proba(xn), yn),
    }
    answers = model.recognize_batch(xm, top_k=1)
    predicted = [answers.class_names[i] for i in answers.top_index[:, 0]]
    true = [known_names[j] for j in yk] + [novel_names[j] for j in yn]
    out.update(metrics.gzsl_figures(true, predicted, is_known))
    return {prefix + k: v for k, v in out.items()}


# ------------------------------------------------------------------------- report
SHOWN = ("known_acc", "nd_known_kept", "nd_novel_detected", "zsl", "gzsl_h")


def procedure_markdown(results: dict[str, Any]) -> list[str]:
    """Markdown per method: each subset's figures, the best order's curve, and the
    adaptive rule at each target against all procedures (paired over splits)."""
    names = list(results.get("procedures") or [])
    if not results.get("procedures_measured") or len(names) < 2:
        return []
    n = len(names)
    durations = np.array(results["durations"], float)
    everything = bits(range(n), n)

    def cell(values: list[float], signed: bool = False) -> str:
        fmt = "{:+.3f}" if signed else "{:.3f}"
        lo, hi = metrics.mean_interval(values, bounds=(-1.0, 1.0) if signed else (0.0, 1.0))
        return f"{fmt.format(float(np.nanmean(values)))} [{fmt.format(lo)}, {fmt.format(hi)}]"

    lines = ["", "## Figures against the procedures used", ""]
    for m, entry in results["methods"].items():
        splits = entry["splits"]
        if not all(f"procs{everything}_known_acc" in s for s in splits):
            continue
        shown = [f for f in SHOWN if f"procs{everything}_{f}" in splits[0]]
        paired = [f for f in ("known_acc", "gzsl_h") if f in shown]
        novel = f"{target_key(results['procedure_targets'][0])}_time_novel" in splits[0]
        lines += [
            f"`{m}`, mean [95 % interval] over {len(splits)} splits. Procedures: "
            + ", ".join(
                f"{j + 1} {p} ({d:g} s)"
                for j, (p, d) in enumerate(zip(names, durations, strict=True))
            )
            + ".",
            "",
            "| procedures | robot time | " + " | ".join(f"`{f}`" for f in shown) + " |",
            "| --- | --- | " + " | ".join("---" for _ in shown) + " |",
        ]
        for subset in subsets(n):
            key = bits(subset, n)
            share = durations[list(subset)].sum() / durations.sum()
            label = " + ".join(str(j + 1) for j in subset)
            cells = [cell([s[f"procs{key}_{f}"] for s in splits]) for f in shown]
            lines.append(f"| {label} | {share:.2f} | " + " | ".join(cells) + " |")
        time_head = "robot time (known / novel)" if novel else "robot time"
        lines += [
            "",
            "Adaptive rule at each target confidence; the differences from all procedures "
            "are paired on the same splits.",
            "",
            f"| target | {time_head} | procedures | "
            + " | ".join(f"`{f}` | − all" for f in paired)
            + " |",
            "| --- | --- | --- | " + " | ".join("--- | ---" for _ in paired) + " |",
        ]
        for t in results["procedure_targets"]:
            p = target_key(t) + "_"
            time = f"{np.mean([s[p + 'time'] for s in splits]):.2f}"
            if novel:
                tk = np.mean([s[p + "time_known"] for s in splits])
                tn = np.mean([s[p + "time_novel"] for s in splits])
                time += f" ({tk:.2f} / {tn:.2f})"
            procs = np.mean([s[p + "procedures"] for s in splits])
            cells = []
            for f in paired:
                diff = [s[p + f] - s[f"procs{everything}_{f}"] for s in splits]
                cells += [cell([s[p + f] for s in splits]), cell(diff, True)]
            lines.append(f"| {t:g} | {time} | {procs:.2f} | " + " | ".join(cells) + " |")
        lines.append("")
    return lines


def plot_procedures(results: dict[str, Any], path: Path, title: str) -> None:
    """known_acc and gzsl_h against robot time: every fixed order's prefixes (grey), the
    adaptive rule at each target (black), all procedures (star)."""
    plt = plots.plt()
    names = list(results["procedures"])
    n = len(names)
    durations = np.array(results["durations"], float)
    m = next(iter(results["methods"]))
    mean = results["methods"][m]["mean"]
    drawn = [f for f in ("known_acc", "gzsl_h") if f"procs{bits(range(n), n)}_{f}" in mean]
    fig, axes = plt.subplots(1, len(drawn), figsize=(5.25 * len(drawn), 4.2), squeeze=False)
    axes = axes[0]
    for ax, figure in zip(axes, drawn, strict=True):
        for order in itertools.permutations(range(n)):
            xs, ys = [0.0], [np.nan]
            for k in range(1, n + 1):
                prefix = sorted(order[:k])
                xs.append(durations[prefix].sum() / durations.sum())
                ys.append(mean[f"procs{bits(prefix, n)}_{figure}"])
            ax.plot(xs[1:], ys[1:], color="0.75", lw=0.8, marker=".", ms=3)
        for j in range(n):
            ax.annotate(
                names[j][:12],
                (durations[j] / durations.sum(), mean[f"procs{bits([j], n)}_{figure}"]),
                fontsize=6,
                color="0.4",
            )
        ts = results["procedure_targets"]
        ax.plot(
            [mean[f"{target_key(t)}_time"] for t in ts],
            [mean[f"{target_key(t)}_{figure}"] for t in ts],
            color="black",
            marker="o",
            ms=4,
            label="adaptive rule (targets " + ", ".join(f"{t:g}" for t in ts) + ")",
        )
        ax.plot([1.0], [mean[f"procs{bits(range(n), n)}_{figure}"]], "k*", ms=11, label="all")
        ax.set(xlabel="share of the whole exploration's robot time", ylabel=figure, xlim=(0, 1.05))
        ax.grid(alpha=0.3)
    axes[0].plot([], [], color="0.75", label="fixed orders, procedure by procedure")
    axes[0].legend(fontsize=7, loc="lower right")
    fig.suptitle(
        f"{title} ({m}, mean over {len(results['methods'][m]['splits'])} splits)", fontsize=10
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
