"""The report of the raw-trial protocol (``app.evaluation.raw``, ``evaluate --dataset
biotac:DIR``): ``report.md`` with every figure's mean, standard deviation and 95 %
confidence interval per method, ``accuracy.png`` (the means as bars with their intervals,
every split's value as a dot) and ``confusion_<method>.png`` (trial confusion matrices
summed over the trial-disjoint splits and over the held-out-pressure fits).

``report.write_report`` hands raw-trial results here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from app.evaluation import plots
from app.evaluation.cells import fmt, fmt_interval
from app.evaluation.procedures import plot_procedures, procedure_markdown
from app.evaluation.raw import raw_figures

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
    return f"a figure of the method's own ({figure}); results.json holds its value per split"


def raw_markdown(results: dict[str, Any], images: dict[str, list[str]] | None = None) -> str:
    """report.md of raw-trial results (``app.evaluation.raw``)."""
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
            cells.append(f"{fmt(mean, std)} {fmt_interval(e.get('ci95', {}).get(f))}")
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
                fmt_interval(results["methods"][m].get("binomial95", {}).get(f)) for m in methods
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
                f"| {s['split']} | " + " | ".join(fmt(s.get(f)) for f in trial_figs) + " |"
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
                    + " | ".join(fmt(row[level]["accuracy"]) for level in levels)
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
    plt = plots.plt()
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
        plots.plot_confusions(
            panels,
            names,
            path,
            f"Trial confusion matrices of {m}, summed over splits (rows: true object)",
        )
        images.setdefault("Trial confusion matrices", []).append(path.name)
        written.append(path)
    if results.get("procedures_measured") and results.get("procedures"):
        path = out / "procedures.png"
        plot_procedures(results, path, "Trial accuracy against robot time, raw BioTac trials")
        images["Figures against the phases used"] = [path.name]
        written.append(path)
    md = out / "report.md"
    md.write_text(raw_markdown(results, images))
    written.insert(0, md)
    return written
