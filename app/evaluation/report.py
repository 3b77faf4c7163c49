"""``evaluate --report DIR``: report.md beside the paper's Tables II-IX, and Figs. 7-8 as PNGs.

Works from the results dict alone (``protocol.evaluate`` or a saved results.json),
so a report can be rebuilt without re-running anything:

- ``report.md``: mean (± std over splits) of every figure per method beside the
  paper's averages; each mean with its 95 % confidence interval and, with several
  methods, the paired differences from the first; per-split tables; wall times; what
  each figure means;
- ``fig7_novelty_<method>.png``: the novelty-threshold tuning curve of split 1
  (accuracy of keeping held-out known trials known and of calling
  validation-novel objects novel, against the threshold; chosen threshold marked);
- ``fig8_confusion_<method>.png``: split 1's ZSL and OSL confusion matrices, rows
  normalised; for ``paper`` ZSL is drawn twice, GEN-F and NEIGHB-F, as in the paper's
  Fig. 8a-c (the title names the panels drawn);
- ``fig8d_jaccard.png``: Jaccard similarity of split 1's novel objects' attribute vectors.

Results of the raw-trial protocol (``app.evaluation.raw``, ``evaluate --dataset
biotac:DIR``) get their own report: ``report.md`` with every figure's mean, standard
deviation and 95 % confidence interval per method, ``accuracy.png`` (the means as bars
with their intervals, every split's value as a dot) and ``confusion_<method>.png`` (trial
confusion matrices summed over the trial-disjoint splits and over the held-out-pressure
fits).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from app.evaluation.metrics import jaccard_similarity, row_normalize
from app.evaluation.procedures import procedure_markdown
from app.evaluation.touches import touch_markdown

# Paper averages (fractions). 6 novel objects: Tables II, III, V, VI, VIII;
# 12 novel objects: means of Table IX's rows (the paper gives no other figure there).
PAPER_6: dict[str, float] = {
    "known_acc": 0.952,
    "nd_known_kept": 0.903,
    "nd_val_novel": 0.953,
    "nd_novel_detected": 0.895,
    "zsl": 0.36,
    "zsl_genf": 0.31,
    "zsl_neighbf": 0.36,
    "zsl_nogan": 0.23,
    "osl": 0.44,
}
PAPER_12: dict[str, float] = {
    "zsl": float(np.mean([24, 19, 18, 13, 14, 13, 15]) / 100),
    "zsl_genf": float(np.mean([17, 19, 10, 17, 14, 14, 13]) / 100),
    "zsl_neighbf": float(np.mean([24, 19, 18, 13, 14, 13, 15]) / 100),
    "osl": float(np.mean([31, 30, 24, 27, 31, 27, 34]) / 100),
}
PAPER_SOURCE: dict[str, str] = {
    "known_acc": "Table III",
    "nd_known_kept": "Table II, X_te",
    "nd_val_novel": "Table II, X_val",
    "nd_novel_detected": "Table II, X_Z",
    "zsl": "Table V NEIGHB-F (12: Table IX)",
    "zsl_genf": "Table V GEN-F (12: Table IX)",
    "zsl_neighbf": "Table V NEIGHB-F (12: Table IX)",
    "zsl_nogan": "Table VI No-GAN",
    "osl": "Table VIII (12: Table IX)",
}
DESCRIPTIONS: dict[str, str] = {
    "known_acc": "accuracy on held-out trials of known objects "
    "(argmax of the known-class classifier)",
    "nd_known_kept": "novelty tuning: held-out known trials called known, at the tuned threshold",
    "nd_val_novel": "novelty tuning: validation-novel objects called novel, at the tuned threshold",
    "nd_novel_detected": "test novel objects' samples called novel",
    "nd_auroc": "AUROC of the novelty score, held-out known trials vs novel test samples",
    "zsl": "zero-shot accuracy among the novel objects",
    "zsl_genf": "paper pipeline, FC_Z trained on generated features (GEN-F)",
    "zsl_neighbf": "paper pipeline, FC_Z trained on nearest real features (NEIGHB-F; = zsl)",
    "zsl_nogan": "paper pipeline, NEIGHB-F with G from Algorithm 1 only (no GAN)",
    "osl": "accuracy among the novel objects after one real sample per novel object",
    "gzsl_seen": "full pipeline on mixed known+novel test set: accuracy on known samples",
    "gzsl_unseen": "full pipeline on mixed known+novel test set: accuracy on novel samples",
    "gzsl_h": "harmonic mean of gzsl_seen and gzsl_unseen",
    "nd_test_kept": "held-out known test trials called known at the tuned threshold",
    "nd_balance": "the smaller of nd_test_kept and nd_novel_detected",
    "ceil_nd_test_kept": "held-out known test trials called known at the oracle threshold "
    "(chosen on the test samples to maximise ceil_nd_balance)",
    "ceil_nd_novel_detected": "novel test samples called novel at the oracle threshold",
    "ceil_nd_balance": "ceiling: the smaller of the two at the best threshold for this score, "
    "chosen on the test samples themselves",
    "ceil_gzsl_seen": "ceiling: mixed test set under perfect routing, known samples (= known_acc)",
    "ceil_gzsl_unseen": "ceiling: mixed test set under perfect routing, novel samples (= zsl)",
    "ceil_gzsl_h": "ceiling: harmonic mean of ceil_gzsl_seen and ceil_gzsl_unseen",
}
ORDER: tuple[str, ...] = (
    "known_acc", "nd_known_kept", "nd_val_novel", "nd_novel_detected", "nd_auroc",
    "zsl", "zsl_genf", "zsl_neighbf", "zsl_nogan", "osl", "gzsl_seen", "gzsl_unseen", "gzsl_h",
    "nd_test_kept", "nd_balance", "ceil_nd_test_kept", "ceil_nd_novel_detected",
    "ceil_nd_balance", "ceil_gzsl_seen", "ceil_gzsl_unseen", "ceil_gzsl_h",
)  # fmt: skip


def paper_figures(n_novel: int) -> dict[str, float]:
    return PAPER_6 if n_novel == 6 else PAPER_12 if n_novel == 12 else {}


def _fmt(v: Any, std: Any = None) -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "—"
    return f"{v:.3f}" if std is None else f"{v:.3f} ± {std:.3f}"


def _figures_present(results: dict[str, Any]) -> list[str]:
    present = set()
    for entry in results["methods"].values():
        present |= set(entry.get("mean", {}))
    return [f for f in ORDER if f in present] + sorted(present - set(ORDER))


def markdown(results: dict[str, Any], images: dict[str, list[str]] | None = None) -> str:
    methods = list(results["methods"])
    n_novel = int(results["novel"])
    paper = paper_figures(n_novel)
    figures = _figures_present(results)
    lines = [
        f"# Evaluation on {results['dataset']}: {n_novel} novel objects, "
        f"{results['splits']} splits, seed {results['seed']}",
        "",
        f"Known objects' test data: {results.get('test_trials', '?')} held-out trials per object; "
        "novel objects: one trial gives the one-shot sample, the others are the test set "
        "(shared by ZSL, OSL and the mixed known/novel test). "
        "Means over splits ± standard deviation.",
        "",
        "## Mean figures beside the paper",
        "",
        "| figure | published paper | " + " | ".join(methods) + " |",
        "| --- | --- | " + " | ".join("---" for _ in methods) + " |",
    ]
    for f in figures:
        cells = [
            _fmt(
                results["methods"][m].get("mean", {}).get(f),
                results["methods"][m].get("std", {}).get(f),
            )
            for m in methods
        ]
        lines.append(f"| `{f}` | {_fmt(paper.get(f))} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Published paper: the averages of its tables, on its own protocol (6000 augmented "
        "32 × 30 samples, known test samples sharing trials with training): "
        + "; ".join(f"`{f}` {PAPER_SOURCE[f]}" for f in PAPER_SOURCE if f in paper)
        + ". The paper's reference [38] (attribute-based haptic ZSL) averages 0.36 (Table VII)."
        if paper
        else "The paper reports no figures for this number of novel objects.",
    ]
    lines += _interval_sections(results, figures)
    lines += touch_markdown(results)
    lines += procedure_markdown(results)
    lines += [
        "",
        "## Wall time",
        "",
        "| method | total s | mean fit s per split |",
        "| --- | --- | --- |",
    ]
    for m in methods:
        entry = results["methods"][m]
        fits = [d.get("timings", {}).get("fit_s") for d in entry.get("details", [])]
        fits = [f for f in fits if f is not None]
        mean_fit = f"{np.mean(fits):.1f}" if fits else "—"
        lines.append(f"| {m} | {entry.get('elapsed_s', float('nan')):.1f} | {mean_fit} |")
    lines += ["", "## Figures", ""]
    for f in figures:
        lines.append(f"- `{f}`: {DESCRIPTIONS.get(f, '')}")
    lines += ["", "## Per split", ""]
    for m in methods:
        splits = results["methods"][m]["splits"]
        method_figs = [f for f in figures if f in results["methods"][m].get("mean", {})]
        lines += [
            f"### {m}",
            "",
            "| split | novel objects | " + " | ".join(f"`{f}`" for f in method_figs) + " |",
            "| --- | --- | " + " | ".join("---" for _ in method_figs) + " |",
        ]
        for i, s in enumerate(splits):
            objs = ", ".join(
                f"{o} {n}" for o, n in zip(s["novel_objects"], s["novel_names"], strict=True)
            )
            lines.append(
                f"| {s.get('split', i + 1)} | {objs} | "
                + " | ".join(_fmt(s.get(f)) for f in method_figs)
                + " |"
            )
        lines.append("")
    if images:
        lines += ["## Split 1", ""]
        for title, files in images.items():
            lines.append(f"### {title}")
            lines.append("")
            lines += [f"![{title}]({name})" for name in files]
            lines.append("")
    return "\n".join(lines) + "\n"


def _fmt_ci(mean: Any, ci: Any, signed: bool = False) -> str:
    """``0.612 [0.590, 0.634]``; ``—`` when not measured; the mean alone without an interval."""
    if mean is None or (isinstance(mean, float) and not np.isfinite(mean)):
        return "—"
    fmt = "{:+.3f}" if signed else "{:.3f}"
    if not ci or any(v is None or not np.isfinite(v) for v in ci):
        return fmt.format(mean)
    return f"{fmt.format(mean)} [{fmt.format(ci[0])}, {fmt.format(ci[1])}]"


def _interval_sections(results: dict[str, Any], figures: list[str]) -> list[str]:
    """Each mean with its 95 % interval, and the paired differences from the reference
    method, when the results have them (results written before they existed have not)."""
    methods = list(results["methods"])
    if not any("ci95" in results["methods"][m] for m in methods):
        return []
    lines = [
        "",
        "## Means with their 95 % confidence intervals",
        "",
        f"{results.get('intervals', 'Student-t 95 % interval of the mean over splits.')}",
        "",
        "| figure | " + " | ".join(methods) + " |",
        "| --- | " + " | ".join("---" for _ in methods) + " |",
    ]
    for f in figures:
        cells = [
            _fmt_ci(
                results["methods"][m].get("mean", {}).get(f),
                results["methods"][m].get("ci95", {}).get(f),
            )
            for m in methods
        ]
        lines.append(f"| `{f}` | " + " | ".join(cells) + " |")
    if any("rerun95" in results["methods"][m] for m in methods):
        lines += [
            "",
            "## Where a re-run lands",
            "",
            f"The range in which the mean of the same command on another seed with "
            f"{results.get('rerun_splits')} splits lands, 95 % (a bootstrap prediction "
            "interval over the splits' values: a confidence interval holds the true mean and "
            "catches a re-run's mean less often, since that moves too).",
            "",
            "| figure | " + " | ".join(methods) + " |",
            "| --- | " + " | ".join("---" for _ in methods) + " |",
        ]
        for f in figures:
            cells = [
                _fmt_interval(results["methods"][m].get("rerun95", {}).get(f)) for m in methods
            ]
            lines.append(f"| `{f}` | " + " | ".join(cells) + " |")
    paired = results.get("paired") or {}
    others = list(paired.get("methods", {}))
    if others:
        ref = paired["reference"]
        lines += [
            "",
            f"## Paired differences from `{ref}`",
            "",
            f"Each method minus `{ref}` on the same splits: mean [95 % interval], and the "
            "splits on which it is above / below.",
            "",
            "| figure | " + " | ".join(f"{m} − {ref}" for m in others) + " |",
            "| --- | " + " | ".join("---" for _ in others) + " |",
        ]
        for f in figures:
            if not any(f in paired["methods"][m]["mean"] for m in others):
                continue
            cells = []
            for m in others:
                p = paired["methods"][m]
                if f not in p["mean"]:
                    cells.append("—")
                    continue
                cells.append(
                    f"{_fmt_ci(p['mean'][f], p['ci95'].get(f), signed=True)} "
                    f"({p['won'][f]} / {p['lost'][f]})"
                )
            lines.append(f"| `{f}` | " + " | ".join(cells) + " |")
    return lines


# ---------------------------------------------------------------------- plots
def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_tuning_curve(curve: dict[str, Any], path: Path, title: str) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=120)
    t = np.asarray(curve["thresholds"], dtype=float)
    ax.plot(t, curve["known_kept"], color="tab:blue", label="held-out known trials called known")
    ax.plot(t, curve["val_novel"], color="tab:red", label="validation-novel objects called novel")
    ax.plot(
        t,
        (np.asarray(curve["known_kept"]) + np.asarray(curve["val_novel"])) / 2,
        color="0.5",
        linestyle=":",
        label="mean (maximised)",
    )
    ax.axvline(
        curve["threshold"],
        color="k",
        linestyle="--",
        label=f"chosen threshold {curve['threshold']:.3g}",
    )
    ax.set_xlabel("novelty threshold (score above = novel)")
    ax.set_ylabel("accuracy")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(title)
    ax.legend(loc="center right", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _matrix_panel(
    ax,
    matrix: np.ndarray,
    labels: list[str],
    title: str,
    vmax: float = 1.0,
    xlabel: str = "predicted",
    ylabel: str = "true",
    ylabels: bool = True,
) -> Any:
    im = ax.imshow(matrix, cmap="Blues", vmin=0, vmax=vmax)
    n = len(labels)
    ax.set_xticks(range(n), labels, rotation=45, ha="right", fontsize=7)
    ax.set_yticks(range(n), labels if ylabels else [""] * n, fontsize=7)
    fontsize = 8 if n <= 8 else 6
    for i in range(n):
        for j in range(n):
            v = matrix[i, j]
            ax.text(
                j,
                i,
                f"{v:.2f}",
                ha="center",
                va="center",
                fontsize=fontsize,
                color="white" if v > 0.6 * vmax else "black",
            )
    ax.set_title(title, fontsize=9)
    ax.set_xlabel(xlabel, fontsize=8)
    ax.set_ylabel(ylabel, fontsize=8)
    return im


def plot_confusions(
    panels: list[tuple[str, np.ndarray]], labels: list[str], path: Path, title: str
) -> None:
    plt = _plt()
    n = len(labels)
    size = max(3.6, 0.45 * n + 1.6)
    fig, axes = plt.subplots(
        1,
        len(panels),
        figsize=(size * len(panels) + 1.5, size + 1.4),
        dpi=120,
        squeeze=False,
        layout="constrained",
    )
    im = None
    for i, (ax, (name, cm)) in enumerate(zip(axes[0], panels, strict=True)):
        im = _matrix_panel(
            ax,
            row_normalize(np.asarray(cm)),
            labels,
            name,
            ylabel="true" if i == 0 else "",
            ylabels=i == 0,
        )
    fig.colorbar(im, ax=axes[0].tolist(), shrink=0.8, label="fraction of the true class")
    fig.suptitle(title, fontsize=10)
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)


def plot_jaccard(vectors: np.ndarray, labels: list[str], path: Path, title: str) -> None:
    plt = _plt()
    n = len(labels)
    size = max(3.6, 0.45 * n + 1.6)
    fig, ax = plt.subplots(figsize=(size + 0.8, size + 0.4), dpi=120)
    im = _matrix_panel(ax, jaccard_similarity(vectors), labels, title, xlabel="", ylabel="")
    fig.colorbar(im, ax=ax, shrink=0.8, label="Jaccard similarity of attribute vectors")
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)


# The paper's Fig. 8a, 8b and 8c, in the names of the panels that draw them.
PAPER_FIG8_PANELS = ("ZSL GEN-F", "ZSL NEIGHB-F", "OSL")


def confusion_title(panels: list[str], method: str) -> str:
    """The title of a method's confusion figure, naming the panels it draws: "Fig. 8a-c"
    only for the paper's three (GEN-F, NEIGHB-F, OSL); another method's ZSL and OSL
    panels are Fig. 8's kind of figure, not its panels."""
    figure = "Fig. 8a-c" if tuple(panels) == PAPER_FIG8_PANELS else "Fig. 8"
    listed = panels[0] if len(panels) == 1 else ", ".join(panels[:-1]) + " and " + panels[-1]
    matrices = "matrix" if len(panels) == 1 else "matrices"
    return f"{figure}: split 1 confusion {matrices} of {listed}, {method}"


def _short(labels: list[str]) -> list[str]:
    return [
        f"z{i + 1} {n}" if len(n) <= 24 else f"z{i + 1} {n[:22]}…" for i, n in enumerate(labels)
    ]


def write_report(
    results: dict[str, Any], out_dir: str | Path, novel_attributes: np.ndarray | None = None
) -> list[Path]:
    """Write report.md and the PNGs into ``out_dir``; returns the files written.

    ``novel_attributes``: split 1's novel objects' attribute vectors for Fig. 8d;
    when omitted they are read from the results (``split_definitions``), if present.
    Raw-trial results (``results["protocol"] == "raw-trials"``) get ``write_raw_report``.
    """
    from app.evaluation.raw import PROTOCOL

    if results.get("protocol") == PROTOCOL:
        return write_raw_report(results, out_dir)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    images: dict[str, list[str]] = {}
    first_split = None
    for m, entry in results["methods"].items():
        if not entry.get("splits"):
            continue
        first_split = first_split or entry["splits"][0]
        labels = _short(list(entry["splits"][0]["novel_names"]))
        details = (entry.get("details") or [{}])[0]
        curve = details.get("novelty_tuning")
        if curve:
            path = out / f"fig7_novelty_{m}.png"
            plot_tuning_curve(curve, path, f"Fig. 7: novelty threshold tuning, split 1, {m}")
            images.setdefault("Fig. 7: novelty threshold tuning", []).append(path.name)
            written.append(path)
        panels = []
        if "confusion_zsl_genf" in details:
            panels.append(("ZSL GEN-F", details["confusion_zsl_genf"]))
            panels.append(
                ("ZSL NEIGHB-F", details.get("confusion_zsl_neighbf", details.get("confusion_zsl")))
            )
        elif "confusion_zsl" in details:
            panels.append(("ZSL", details["confusion_zsl"]))
        if "confusion_osl" in details:
            panels.append(("OSL", details["confusion_osl"]))
        if panels:
            path = out / f"fig8_confusion_{m}.png"
            plot_confusions(panels, labels, path, confusion_title([n for n, _ in panels], m))
            images.setdefault("Fig. 8: split 1 confusion matrices", []).append(path.name)
            written.append(path)
    if novel_attributes is None:
        defs = results.get("split_definitions") or []
        if defs and "novel_attributes" in defs[0]:
            novel_attributes = np.asarray(defs[0]["novel_attributes"])
    if novel_attributes is not None and first_split is not None:
        path = out / "fig8d_jaccard.png"
        plot_jaccard(
            np.asarray(novel_attributes),
            _short(list(first_split["novel_names"])),
            path,
            "Fig. 8d: attribute similarity of split 1's novel objects",
        )
        images["Fig. 8d: attribute similarity of the novel objects"] = [path.name]
        written.append(path)
    if results.get("touches"):
        from app.evaluation.touches import plot_touches

        path = out / "touches.png"
        plot_touches(
            results,
            path,
            f"After k touches answered as one, and after one enrolled touch\n"
            f"{results['splits']} splits, {results['novel']} novel objects",
        )
        images["Touches and one enrolled touch"] = [path.name]
        written.append(path)
    if results.get("procedures_measured"):
        from app.evaluation.procedures import plot_procedures

        path = out / "procedures.png"
        plot_procedures(
            results,
            path,
            f"Known accuracy and gzsl_h against robot time, {results['novel']} novel objects",
        )
        images["Figures against the procedures used"] = [path.name]
        written.append(path)
    md = out / "report.md"
    md.write_text(markdown(results, images))
    written.insert(0, md)
    return written


def write_report_from_file(results_json: str | Path, out_dir: str | Path) -> list[Path]:
    return write_report(json.loads(Path(results_json).read_text()), out_dir)


# --------------------------------------------------------------- raw BioTac trials
RAW_DESCRIPTIONS: dict[str, str] = {
    "known_acc": "held-out trials recognised as their object: one answer per trial, from both "
    "fingers' images (probabilities averaged)",
    "known_acc_finger": "held-out tactile images (one finger each) whose most probable known "
    "class is their object: the same models without fusing the fingers",
    "nd_known_kept": "held-out trials of known objects that novelty detection calls known",
    "pressure_mean": "held-out grip pressure: the mean over the held-out pressures of one repeat",
}


def _raw_description(figure: str) -> str:
    if figure in RAW_DESCRIPTIONS:
        return RAW_DESCRIPTIONS[figure]
    if figure.startswith("pressure_"):
        return (
            f"trained on the other grip pressures, trial accuracy on the trials gripped at "
            f"{figure.removeprefix('pressure_')} (held out)"
        )
    return ""


def _fmt_interval(ci: Any) -> str:
    if not ci or any(v is None or not np.isfinite(v) for v in ci):
        return "—"
    return f"[{ci[0]:.3f}, {ci[1]:.3f}]"


def raw_markdown(results: dict[str, Any], images: dict[str, list[str]] | None = None) -> str:
    """report.md of raw-trial results (``app.evaluation.raw``)."""
    from app.evaluation.raw import raw_figures

    methods = list(results["methods"])
    figures = raw_figures(results)
    cfg = results.get("config", {})
    pressures = ", ".join(f"{p:g}" for p in results.get("pressures", []))
    lines = [
        f"# Raw BioTac trials on {results['dataset']}: known objects, "
        f"{results['splits']} splits, seed {results['seed']}"
        + (" (validation trials only)" if results.get("validation") else ""),
        "",
        f"{cfg.get('n_trials', '?')} trials of {cfg.get('n_objects', '?')} objects "
        f"({', '.join(cfg.get('class_names', []))}), "
        f"{cfg.get('n_attributes', 0)} attributes. Every model is fitted on raw training "
        "trials (its tactile-image featurizer too) and answers once per test trial from all "
        "of its fingers.",
        "",
        f"- Trial-disjoint splits: {results['splits']} random splits, "
        f"{results.get('test_trials', '?')} whole test trials per object, the rest train; a "
        "method's seed is the evaluation seed plus the split index.",
    ]
    if results.get("validation"):
        lines.append(
            "- Validation: no test trial is used. Each split's training trials are split again "
            "(the same number of trials per object validate); each held-out pressure is "
            "stood for by fitting on one other pressure and validating on the remaining one, "
            "both ways."
        )
    if pressures:
        lines.append(
            f"- Held-out grip pressure ({pressures}): train on the other pressures, test on "
            f"the held-out one's trials; each fitted {results['splits']} times with method "
            "seeds seed, seed + 1, …, so its spread is the methods' own randomness."
        )
    lines += [
        "",
        "Mean ± sample standard deviation over splits (repeats), and the 95 % confidence "
        "interval of the mean (Student's t; splits share trials, so it understates the "
        "uncertainty about new trials).",
        "",
        "## Figures",
        "",
        "| figure | " + " | ".join(methods) + " |",
        "| --- | " + " | ".join("---" for _ in methods) + " |",
    ]
    for f in figures:
        cells = []
        for m in methods:
            e = results["methods"][m]
            mean, std = e.get("mean", {}).get(f), e.get("std", {}).get(f)
            cells.append(f"{_fmt(mean, std)} {_fmt_interval(e.get('ci95', {}).get(f))}")
        lines.append(f"| `{f}` | " + " | ".join(cells) + " |")
    binomial = [
        f for f in figures if any(f in results["methods"][m].get("binomial95", {}) for m in methods)
    ]
    if binomial:
        lines += [
            "",
            "A held-out pressure's test set is its trials, the same in every repeat: the "
            "Wilson 95 % interval of each mean accuracy for that many test trials says how "
            "much the figure itself could move with other trials.",
            "",
            "| figure | test trials | " + " | ".join(methods) + " |",
            "| --- | --- | " + " | ".join("---" for _ in methods) + " |",
        ]
        for f in binomial:
            level = float(f.removeprefix("pressure_"))
            first = results["methods"][methods[0]].get("pressure", [])
            n = next((p["n_test_trials"] for p in first if p["pressure"] == level), "?")
            cells = [
                _fmt_interval(results["methods"][m].get("binomial95", {}).get(f)) for m in methods
            ]
            lines.append(f"| `{f}` | {n} | " + " | ".join(cells) + " |")
    lines += procedure_markdown(results)
    lines += ["", "## What each figure is", ""]
    lines += [f"- `{f}`: {_raw_description(f)}" for f in figures]
    lines += [
        "",
        "## Wall time",
        "",
        "| method | total s | mean fit s |",
        "| --- | --- | --- |",
    ]
    for m in methods:
        e = results["methods"][m]
        fits = [d["timings"]["fit_s"] for d in e.get("details", [])]
        fits += [p["fit_s"] for p in e.get("pressure", [])]
        lines.append(
            f"| {m} | {e.get('elapsed_s', float('nan')):.1f} | "
            f"{np.mean(fits) if fits else float('nan'):.1f} |"
        )
    lines += ["", "## Per split", ""]
    trial_figs = [f for f in figures if not f.startswith("pressure_")]
    for m in methods:
        lines += [
            f"### {m}",
            "",
            "| split | " + " | ".join(f"`{f}`" for f in trial_figs) + " |",
            "| --- | " + " | ".join("---" for _ in trial_figs) + " |",
        ]
        for s in results["methods"][m]["splits"]:
            lines.append(
                f"| {s['split']} | " + " | ".join(_fmt(s.get(f)) for f in trial_figs) + " |"
            )
        repeats = results["methods"][m].get("pressure", [])
        if repeats:
            levels = sorted({p["pressure"] for p in repeats})
            lines += [
                "",
                "| repeat (seed) | "
                + " | ".join(f"held-out pressure {level:g}" for level in levels)
                + " |",
                "| --- | " + " | ".join("---" for _ in levels) + " |",
            ]
            for r in sorted({p["repeat"] for p in repeats}):
                row = {p["pressure"]: p for p in repeats if p["repeat"] == r}
                seed = next(iter(row.values()))["seed"]
                lines.append(
                    f"| {r} ({seed}) | "
                    + " | ".join(_fmt(row[level]["accuracy"]) for level in levels)
                    + " |"
                )
        lines.append("")
    if images:
        lines += ["## Plots", ""]
        for title, files in images.items():
            lines += [f"### {title}", ""]
            lines += [f"![{title}]({name})" for name in files]
            lines.append("")
    return "\n".join(lines) + "\n"


def plot_raw_accuracy(results: dict[str, Any], path: Path, title: str) -> None:
    """Grouped bars: each figure's mean per method, the 95 % interval as an error bar and
    every split's (repeat's) value as a dot."""
    from app.evaluation.raw import raw_figures

    plt = _plt()
    methods = list(results["methods"])
    figures = [f for f in raw_figures(results) if f != "pressure_mean"]
    values: dict[tuple[str, str], list[float]] = {}
    for m in methods:
        e = results["methods"][m]
        for f in figures:
            if f.startswith("pressure_"):
                level = float(f.removeprefix("pressure_"))
                values[m, f] = [p["accuracy"] for p in e["pressure"] if p["pressure"] == level]
            else:
                values[m, f] = [s[f] for s in e["splits"]]
    width = 0.8 / max(len(methods), 1)
    fig, ax = plt.subplots(figsize=(1.6 * len(figures) + 2.5, 4.4), dpi=120)
    x = np.arange(len(figures))
    colors = plt.get_cmap("tab10")
    for i, m in enumerate(methods):
        e = results["methods"][m]
        pos = x - 0.4 + width * (i + 0.5)
        means = np.array([e["mean"].get(f, np.nan) for f in figures], dtype=float)
        cis = [e.get("ci95", {}).get(f) or [np.nan, np.nan] for f in figures]
        lo = np.array([c[0] if c[0] is not None else np.nan for c in cis], dtype=float)
        hi = np.array([c[1] if c[1] is not None else np.nan for c in cis], dtype=float)
        err = np.vstack([np.nan_to_num(means - lo), np.nan_to_num(hi - means)])
        ax.bar(pos, means, width * 0.9, color=colors(i), alpha=0.75, label=m)
        ax.errorbar(pos, means, yerr=err, fmt="none", ecolor="k", capsize=3, linewidth=1)
        for j, f in enumerate(figures):
            v = np.asarray(values[m, f], dtype=float)
            jitter = (np.arange(len(v)) - (len(v) - 1) / 2) * (width * 0.5 / max(len(v), 1))
            ax.scatter(pos[j] + jitter, v, s=6, color="k", alpha=0.5, zorder=3, linewidths=0)
    ax.set_xticks(x, [f"{f}" for f in figures], rotation=15, ha="right", fontsize=8)
    ax.set_ylabel("accuracy (trials; images for known_acc_finger)")
    low = min(
        [0.5]
        + [
            float(np.nanmin(v))
            for v in (np.asarray(vals, dtype=float) for vals in values.values())
            if len(v)
        ]
    )
    ax.set_ylim(max(0.0, low - 0.05), 1.01)
    ax.set_title(title, fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def write_raw_report(results: dict[str, Any], out_dir: str | Path) -> list[Path]:
    """report.md, accuracy.png and confusion_<method>.png of raw-trial results."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    images: dict[str, list[str]] = {}
    path = out / "accuracy.png"
    plot_raw_accuracy(
        results,
        path,
        f"Raw BioTac trials ({results['dataset']}): mean accuracy, 95 % CI, every split",
    )
    images["Accuracy per method"] = [path.name]
    written.append(path)
    labels = list(results.get("config", {}).get("class_names", []))
    for m, entry in results["methods"].items():
        panels = [("trial-disjoint splits", entry["confusion"])]
        if entry.get("pressure"):
            panels.append(("held-out grip pressure", entry["confusion_pressure"]))
        names = labels or [str(i) for i in range(len(entry["confusion"]))]
        path = out / f"confusion_{m}.png"
        plot_confusions(
            panels,
            names,
            path,
            f"Trial confusion matrices of {m}, summed over splits (rows: true object)",
        )
        images.setdefault("Trial confusion matrices", []).append(path.name)
        written.append(path)
    if results.get("procedures_measured") and results.get("procedures"):
        from app.evaluation.procedures import plot_procedures

        path = out / "procedures.png"
        plot_procedures(results, path, "Trial accuracy against robot time, raw BioTac trials")
        images["Figures against the phases used"] = [path.name]
        written.append(path)
    md = out / "report.md"
    md.write_text(raw_markdown(results, images))
    written.insert(0, md)
    return written
