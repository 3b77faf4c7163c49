"""Curves a robot operator needs, on the splits of ``protocol.evaluate``.

**Touches.** A robot may touch one object several times before it answers. After k touches
the service's ``POST /v1/recognize?same_object=true`` answers once from all of them: the
mean of their known-class probabilities, novel-class probabilities and novelty scores
(``TactileRecognizer.recognize_batch`` with ``groups``). Here the test samples of each
object are dealt into groups of k samples from k distinct trials (drawn per split; an
object's trials that do not fill a group are left out), and every group is answered as
one object:

- ``touches{k}_known_acc``: the known objects' groups, by the fused known-class posterior;
- ``touches{k}_nd_known_kept`` / ``touches{k}_nd_novel_detected``: groups of known objects
  whose fused novelty score stays at or below the tuned threshold / groups of novel objects
  above it;
- ``touches{k}_zsl``: the novel objects' groups, by the fused zero-shot posterior;
- ``touches{k}_gzsl_seen`` / ``_unseen`` / ``_h``: the full pipeline on the known and novel
  groups mixed, novelty detection routing each group.

With k = 1 every group is one test sample, and the figures are the protocol's own. Known
objects have ``test_trials`` held-out trials each, so k runs up to ``test_trials``: the
protocol holds out more trials of every known object for larger k (``--test-trials``), and
trains on fewer.

**After one real touch.** ``osl_gzsl_seen`` / ``_unseen`` / ``_h``: the full pipeline on the
mixed test samples once every novel object has its one enrolled sample (the one-shot model
of ``osl``): what a robot sees after an operator enrols one touch of each new object.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from app.evaluation import metrics, plots
from app.framework.recognizer import TactileRecognizer, group_mean

OSL_GZSL_FIGURES: tuple[str, ...] = ("osl_gzsl_seen", "osl_gzsl_unseen", "osl_gzsl_h")
PER_TOUCHES: tuple[str, ...] = metrics.MIXED_FIGURES


def touch_figures(touches: Sequence[int]) -> tuple[str, ...]:
    """The figures ``measure`` adds for these touch counts."""
    if not touches:
        return ()
    return OSL_GZSL_FIGURES + tuple(f"touches{k}_{f}" for k in touches for f in PER_TOUCHES)


def check_touches(touches: Sequence[int], test_trials: int) -> list[int]:
    """Touch counts sorted and distinct; ValueError naming the problem when one is not a
    positive integer or exceeds the known objects' held-out trials."""
    out = sorted(set(int(k) for k in touches))
    if any(k < 1 for k in out):
        raise ValueError(f"touch counts must be positive integers, got {list(touches)}")
    if out and out[-1] > test_trials:
        raise ValueError(
            f"{out[-1]} touches of a known object need {out[-1]} of its held-out trials; "
            f"hold out that many with --test-trials {out[-1]} (now {test_trials})"
        )
    return out


def touch_groups(objects: np.ndarray, trials: np.ndarray, k: int, rng) -> tuple[np.ndarray, int]:
    """(group of each sample, -1 where left out; the number of groups): each object's
    trials shuffled and dealt k at a time, every sample of a trial in its trial's group."""
    group = np.full(len(objects), -1, np.int64)
    n = 0
    for obj in np.unique(objects):
        own = np.unique(trials[objects == obj])
        own = own[rng.permutation(len(own))]
        for start in range(0, len(own) - k + 1, k):
            group[(objects == obj) & np.isin(trials, own[start : start + k])] = n
            n += 1
    return group, n


def measure(
    zsl_model: TactileRecognizer,
    osl_model: TactileRecognizer,
    known: tuple[np.ndarray, np.ndarray, np.ndarray],
    novel: tuple[np.ndarray, np.ndarray, np.ndarray],
    known_names: Sequence[str],
    novel_names: Sequence[str],
    touches: Sequence[int],
    rng,
) -> dict[str, float]:
    """The figures of ``touch_figures(touches)`` for one split. ``known`` and ``novel``:
    (samples, class index, trial id) of the known and the novel test samples."""
    (xk, yk, tk), (xn, yn, tn) = known, novel
    x = np.concatenate([xk, xn])
    is_known = np.r_[np.ones(len(xk), bool), np.zeros(len(xn), bool)]
    true = [known_names[j] for j in yk] + [novel_names[j] for j in yn]
    out: dict[str, float] = {}
    answers = osl_model.recognize_batch(x, top_k=1)
    predicted = [answers.class_names[i] for i in answers.top_index[:, 0]]
    for name, value in metrics.gzsl_figures(true, predicted, is_known).items():
        out[f"osl_{name}"] = value

    threshold = zsl_model.novelty_threshold
    score_k, score_n = zsl_model.novelty_score(xk), zsl_model.novelty_score(xn)
    known_p, novel_p = zsl_model.known_proba(xk), zsl_model.novel_proba(xn)
    for k in touches:
        gk, nk = touch_groups(yk, tk, k, rng)
        gn, nn = touch_groups(yn, tn, k, rng)
        mk, mn = gk >= 0, gn >= 0
        label_k = np.zeros(nk, np.int64)
        label_k[gk[mk]] = yk[mk]
        label_n = np.zeros(nn, np.int64)
        label_n[gn[mn]] = yn[mn]
        prefix = f"touches{k}_"
        fused_known = group_mean(known_p[mk], gk[mk], nk)
        out[prefix + "known_acc"] = metrics.argmax_accuracy(fused_known, label_k)
        out[prefix + "nd_known_kept"] = float(
            np.mean(group_mean(score_k[mk], gk[mk], nk) <= threshold)
        )
        out[prefix + "nd_novel_detected"] = metrics.detection_rate(
            group_mean(score_n[mn], gn[mn], nn), threshold
        )
        out[prefix + "zsl"] = metrics.argmax_accuracy(group_mean(novel_p[mn], gn[mn], nn), label_n)
        fused = zsl_model.recognize_batch(
            np.concatenate([xk[mk], xn[mn]]), top_k=1, groups=np.r_[gk[mk], gn[mn] + nk]
        )
        predicted = [fused.class_names[i] for i in fused.top_index[:, 0]]
        truth = [known_names[j] for j in label_k] + [novel_names[j] for j in label_n]
        group_known = np.r_[np.ones(nk, bool), np.zeros(nn, bool)]
        for name, value in metrics.gzsl_figures(truth, predicted, group_known).items():
            out[prefix + name] = value
    return out


SHOWN = ("known_acc", "nd_known_kept", "nd_novel_detected", "zsl", "gzsl_h")


def touch_markdown(results: dict[str, Any]) -> list[str]:
    """Markdown tables per method: each figure of ``SHOWN`` after each touch count and the
    paired difference (most touches − 1 touch) on the same splits, and the mixed figure
    after one enrolled touch against the zero-shot one, paired; mean [95 % interval] over
    splits (``metrics.mean_interval``). Nothing without touch figures."""
    touches = list(results.get("touches") or [])
    if not touches:
        return []
    first, last = touches[0], touches[-1]

    def cell(values: list[float], signed: bool = False) -> str:
        fmt = "{:+.3f}" if signed else "{:.3f}"
        lo, hi = metrics.mean_interval(values, bounds=(-1.0, 1.0) if signed else (0.0, 1.0))
        m = float(np.nanmean(values))
        return f"{fmt.format(m)} [{fmt.format(lo)}, {fmt.format(hi)}]"

    lines = ["", "## Touches answered as one, and one enrolled touch", ""]
    for m, entry in results["methods"].items():
        splits = entry["splits"]
        if not all(f"touches{last}_gzsl_h" in s for s in splits):
            continue
        head = [f"{k} touch{'es' if k > 1 else ''}" for k in touches]
        lines += [
            f"`{m}`: mean [95 % interval] over {len(splits)} splits; the last column is "
            f"the paired difference {last} − {first} touches on the same splits.",
            "",
            "| figure | " + " | ".join(head) + f" | {last} − {first} |",
            "| --- | " + " | ".join("---" for _ in head) + " | --- |",
        ]
        for f in SHOWN:
            cells = [cell([s[f"touches{k}_{f}"] for s in splits]) for k in touches]
            diff = [s[f"touches{last}_{f}"] - s[f"touches{first}_{f}"] for s in splits]
            lines.append(f"| `{f}` | " + " | ".join(cells) + f" | {cell(diff, True)} |")
        zero = [s[f"touches{first}_gzsl_h"] for s in splits]
        enrolled = [s["osl_gzsl_h"] for s in splits]
        gain = [b - a for a, b in zip(zero, enrolled, strict=True)]
        seen = np.mean([s["osl_gzsl_seen"] for s in splits])
        unseen = np.mean([s["osl_gzsl_unseen"] for s in splits])
        lines += [
            "",
            "| `gzsl_h` zero-shot | after one enrolled touch | difference (paired) | "
            "seen / unseen after it |",
            "| --- | --- | --- | --- |",
            f"| {cell(zero)} | {cell(enrolled)} | {cell(gain, True)} | {seen:.3f} / {unseen:.3f} |",
            "",
        ]
    return lines


def plot_touches(results: dict[str, Any], path: Path, title: str) -> None:
    """Each method's figures against the number of touches (mean and 95 % interval over
    splits), and its mixed figure after one enrolled touch per novel object."""
    plt = plots.plt()
    touches = list(results["touches"])
    methods = list(results["methods"])
    fig, axes = plt.subplots(1, len(methods), figsize=(5.2 * len(methods), 4.2), squeeze=False)
    for ax, m in zip(axes[0], methods, strict=True):
        entry = results["methods"][m]
        for figure in SHOWN:
            keys = [f"touches{k}_{figure}" for k in touches]
            mean = np.array([entry["mean"].get(key, np.nan) for key in keys], float)
            ci = np.array([entry["ci95"].get(key, [np.nan, np.nan]) for key in keys], float)
            ax.errorbar(
                touches, mean, yerr=np.abs(ci.T - mean), marker="o", ms=4, capsize=3, label=figure
            )
        osl = entry["mean"].get("osl_gzsl_h", np.nan)
        lo, hi = entry["ci95"].get("osl_gzsl_h", [np.nan, np.nan])
        ax.errorbar(
            [touches[0]],
            [osl],
            yerr=[[osl - lo], [hi - osl]],
            marker="*",
            ms=11,
            color="black",
            capsize=3,
            label="gzsl_h after one enrolled touch per novel object",
            ls="none",
        )
        ax.set(
            xticks=touches,
            xlabel="touches of the object, answered as one",
            ylim=(0, 1.02),
            title=m,
        )
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("mean over splits (95 % interval)")
    axes[0][-1].legend(fontsize=7, loc="lower right")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
