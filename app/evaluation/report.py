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

Results of the raw-trial protocol (``results["protocol"] == "raw-trials"``) are handed to
``raw_report.write_raw_report``; the generic figures are drawn by ``plots``.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from app.evaluation.cells import fmt, fmt_ci, fmt_interval
from app.evaluation.plots import plot_confusions, plot_jaccard, plot_tuning_curve
from app.evaluation.procedures import plot_procedures, procedure_markdown
from app.evaluation.raw import PROTOCOL
from app.evaluation.raw_report import plot_raw_accuracy, raw_markdown, write_raw_report
from app.evaluation.touches import plot_touches, touch_markdown

__all__ = [
    "DESCRIPTIONS",
    "ORDER",
    "PAPER_6",
    "PAPER_12",
    "PAPER_FIG8_PANELS",
    "PAPER_SOURCE",
    "confusion_title",
    "describe",
    "markdown",
    "measured_figures",
    "paper_figures",
    "plot_confusions",
    "plot_jaccard",
    "plot_raw_accuracy",
    "plot_tuning_curve",
    "raw_markdown",
    "write_raw_report",
    "write_report",
    "write_report_from_file",
]

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


#: families of figures that have a section of their own (touches, procedures), by prefix:
#: kept out of the tables of means and of the per-split tables, whose rows they would bury
SECTIONED: tuple[str, ...] = ("touches", "osl_gzsl_", "procs", "adaptive")


def paper_figures(n_novel: int) -> dict[str, float]:
    return PAPER_6 if n_novel == 6 else PAPER_12 if n_novel == 12 else {}


def _finite(value: Any) -> bool:
    return isinstance(value, int | float) and math.isfinite(value)


def measured_figures(results: dict[str, Any]) -> list[str]:
    """The figures with a finite mean for at least one method, ``ORDER`` first: a figure that
    no method measured (all NaN, as in results that summarised figures never asked for) gets
    no row of ``—``."""
    present: set[str] = set()
    for entry in results["methods"].values():
        present |= {f for f, v in entry.get("mean", {}).items() if _finite(v)}
    return [f for f in ORDER if f in present] + sorted(present - set(ORDER))


def _figures_present(results: dict[str, Any]) -> list[str]:
    """The measured figures of the report's tables: those of touches and procedures have
    their own sections."""
    return [f for f in measured_figures(results) if not f.startswith(SECTIONED)]


def describe(figure: str) -> str:
    """What ``figure`` is, in a sentence; never empty."""
    if figure in DESCRIPTIONS:
        return DESCRIPTIONS[figure]
    if match := re.fullmatch(r"touches(\d+)_(.+)", figure):
        k, base = match.groups()
        return f"{describe(base)}, after {k} touches of each test object answered as one"
    if figure.startswith("osl_gzsl_"):
        return f"{describe(figure.removeprefix('osl_'))}, after one enrolled touch per novel object"
    if match := re.fullmatch(r"procs([01]+)_(.+)", figure):
        used, base = match.groups()
        return f"{describe(base)}, with only procedures {used} kept (1: kept, in their order)"
    if match := re.fullmatch(r"adaptive(\d+)_(.+)", figure):
        target, base = match.groups()
        return f"{ADAPTIVE.get(base) or describe(base)}, by the adaptive rule at target {target} %"
    if match := re.fullmatch(r"tables(\d+)_zsl_(joint|alone)", figure):
        k, how = match.groups()
        return f"zero-shot accuracy in tables of every novel object, {k} touches each, named " + (
            "jointly (no class twice)" if how == "joint" else "one by one"
        )
    if match := re.fullmatch(r"tables_mixed_(alone_)?(.+)", figure):
        alone, base = match.groups()
        how = "one by one, each touch routed alone" if alone else "jointly (app.framework.tables)"
        return f"{describe(base)}, in tables of the novel objects and as many known, named {how}"
    if figure.startswith("zsl_"):
        return f"zero-shot accuracy among the novel objects, by the method's variant {figure}"
    return f"a figure of the method's own ({figure}); results.json holds its value per split"


ADAPTIVE: dict[str, str] = {
    "time": "mean share of the whole exploration's robot time used",
    "time_known": "mean share of robot time used on known objects' samples",
    "time_novel": "mean share of robot time used on novel objects' samples",
    "procedures": "mean number of procedures used",
}


def _family_lines(results: dict[str, Any]) -> list[str]:
    """One line per family of figures that has a section of its own, if measured."""
    measured = measured_figures(results)
    lines = []
    if touches := results.get("touches"):
        if any(f.startswith("touches") for f in measured):
            ks = ", ".join(str(k) for k in touches)
            lines.append(
                f"- `touches<k>_<figure>` (k = {ks}): the figure after k touches of each test "
                "object answered as one (section Touches)"
            )
        if any(f.startswith("osl_gzsl_") for f in measured):
            lines.append(
                "- `osl_gzsl_seen` / `_unseen` / `_h`: the mixed known + novel figures after "
                "one enrolled touch per novel object"
            )
    if any(f.startswith(("procs", "adaptive")) for f in measured):
        names = ", ".join(results.get("procedures") or [])
        lines += [
            f"- `procs<bits>_<figure>`: the figure with only the procedures whose bit is 1 "
            f"kept, bits in the order {names} (section Figures against the procedures used)",
            "- `adaptive<t>_<figure>`: the figure by the adaptive rule at target confidence "
            "t %; `_time`: its mean share of robot time, `_procedures`: procedures used",
        ]
    return lines


def markdown(results: dict[str, Any], images: dict[str, list[str]] | None = None) -> str:
    methods = list(results["methods"])
    n_novel = int(results["novel"])
    paper = paper_figures(n_novel)
    figures = _figures_present(results)
    lines = [
        f"# Evaluation on {results['dataset']}: {n_novel} novel objects, "
        f"{results['splits']} splits, seed {results['seed']}",
        "",
        "## Mean figures" + (" beside the paper" if paper else ""),
        "",
        "Means over splits ± standard deviation.",
        "",
        # the paper's column only where it has figures for this number of novel objects
        "| figure | " + ("published paper | " if paper else "") + " | ".join(methods) + " |",
        "| --- | " + ("--- | " if paper else "") + " | ".join("---" for _ in methods) + " |",
    ]
    for f in figures:
        cells = [fmt(paper.get(f))] if paper else []
        cells += [
            fmt(
                results["methods"][m].get("mean", {}).get(f),
                results["methods"][m].get("std", {}).get(f),
            )
            for m in methods
        ]
        lines.append(f"| `{f}` | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Published paper: the averages of its tables, on its own protocol (6000 augmented "
        "32 × 30 samples, known test samples sharing trials with training): "
        + "; ".join(f"`{f}` {PAPER_SOURCE[f]}" for f in PAPER_SOURCE if f in paper and f in figures)
        + ". The paper's reference [38] (attribute-based haptic ZSL) averages 0.36 (Table VII)."
        if paper
        else "The paper reports no figures for this number of novel objects.",
        "",
        f"Known objects' test data: {results.get('test_trials', '?')} held-out trials per object; "
        "novel objects: one trial gives the one-shot sample, the others are the test set "
        "(shared by ZSL, OSL and the mixed known/novel test).",
    ]
    lines += _interval_sections(results, figures)
    lines += touch_markdown(results)
    lines += procedure_markdown(results)
    lines += [
        "",
        "## Wall time",
        "",
        "Seconds of fitting and measuring, summed over splits (splits that ran in processes "
        "side by side count each), and the mean over splits of one fit's seconds.",
        "",
        "| method | s, summed over splits | fit s, mean per split |",
        "| --- | --- | --- |",
    ]
    for m in methods:
        entry = results["methods"][m]
        fits = [d.get("timings", {}).get("fit_s") for d in entry.get("details", [])]
        fits = [f for f in fits if f is not None]
        mean_fit = f"{np.mean(fits):.1f}" if fits else "—"
        lines.append(f"| {m} | {entry.get('elapsed_s', float('nan')):.1f} | {mean_fit} |")
    lines += ["", "## Figures", ""]
    lines += [f"- `{f}`: {describe(f)}" for f in figures]
    lines += _family_lines(results)
    lines += ["", "## Per split", ""]
    for m in methods:
        splits = results["methods"][m]["splits"]
        method_figs = [f for f in figures if any(_finite(s.get(f)) for s in splits)]
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
                + " | ".join(fmt(s.get(f)) for f in method_figs)
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
            fmt_ci(
                results["methods"][m].get("mean", {}).get(f),
                results["methods"][m].get("ci95", {}).get(f),
            )
            for m in methods
        ]
        lines.append(f"| `{f}` | " + " | ".join(cells) + " |")
    rerun = {
        f: [fmt_interval(results["methods"][m].get("rerun95", {}).get(f)) for m in methods]
        for f in figures
    }
    rerun = {f: cells for f, cells in rerun.items() if any(c != "—" for c in cells)}
    if rerun:  # none with one split, or in results that predate it
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
        lines += [f"| `{f}` | " + " | ".join(cells) + " |" for f, cells in rerun.items()]
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
            if not any(_finite(paired["methods"][m]["mean"].get(f)) for m in others):
                continue
            cells = []
            for m in others:
                p = paired["methods"][m]
                if not _finite(p["mean"].get(f)):
                    cells.append("—")
                    continue
                cells.append(
                    f"{fmt_ci(p['mean'][f], p['ci95'].get(f), signed=True)} "
                    f"({p['won'][f]} / {p['lost'][f]})"
                )
            lines.append(f"| `{f}` | " + " | ".join(cells) + " |")
    return lines


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
