"""The plain-text tables that ``tactile-zsl evaluate`` prints, each figure once.

Works from the results dict alone (``protocol.evaluate``, ``raw.evaluate_raw`` or a saved
results.json) and changes nothing in it: results.json keeps every figure.

- A row equal to another by definition (``EQUAL_BY_DEFINITION``: ``ceil_gzsl_seen`` is
  ``known_acc``, ``touches1_zsl`` is ``zsl``, …) is left out and named in a note under the
  table, where its values equal the other row's on every split for every method; where
  they do not, it is printed with a note saying why it may differ.
- A figure that only some methods measure (the paper pipeline's ZSL variants) gets a
  table of its own with only those methods' columns, instead of a row of ``—``.
- Methods whose figures are identical on every split in some rows are named under the
  table with those rows; for the forest baselines (``dap``, ``eszsl``, ``extratrees``) the
  note says why: they share one known-class forest, novelty detector and one-shot
  nearest-class-mean (``app.baselines.common``) and differ only in the zero-shot part.
- Timings carry their unit in the row name and a note says what they sum.
- The paired table's won/lost is read as "the column's method beat the reference".
- Every column is as wide as its widest cell, name included.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from typing import Any

from app.evaluation.raw import PROTOCOL, raw_figures
from app.evaluation.report import ORDER, measured_figures

__all__ = [
    "EQUAL_BY_DEFINITION",
    "SHARED_PARTS",
    "fold_equal_rows",
    "identical_rows",
    "raw_summary_table",
    "render",
    "summary_table",
]

# figure -> (the figure it equals by definition, why)
_ONE_TOUCH = "one touch is one test trial, and here one trial is one sample"
EQUAL_BY_DEFINITION: dict[str, tuple[str, str]] = {
    "ceil_gzsl_seen": (
        "known_acc",
        "perfect routing answers known test trials by the known-class classifier",
    ),
    "ceil_gzsl_unseen": ("zsl", "perfect routing answers novel test samples by the zero-shot one"),
    "zsl_neighbf": ("zsl", "the paper pipeline's default enrolment is NEIGHB-F"),
    "osl_gzsl_seen": (
        "gzsl_seen",
        "enrolling one touch per novel object changes neither the novelty score nor the "
        "known-class classifier",
    ),
    "touches1_known_acc": ("known_acc", _ONE_TOUCH),
    "touches1_nd_known_kept": ("nd_test_kept", _ONE_TOUCH),
    "touches1_nd_novel_detected": ("nd_novel_detected", _ONE_TOUCH),
    "touches1_zsl": ("zsl", _ONE_TOUCH),
    "touches1_gzsl_seen": ("gzsl_seen", _ONE_TOUCH),
    "touches1_gzsl_unseen": ("gzsl_unseen", _ONE_TOUCH),
    "touches1_gzsl_h": ("gzsl_h", _ONE_TOUCH),
    "tables1_zsl_alone": (
        "zsl",
        "the 1-touch tables hold every novel test trial once, each table every novel object",
    ),
}

#: why the forest baselines print the same figures in many rows
SHARED_PARTS = (
    "by design: the forest baselines share one known-class extra-trees forest (same seed on "
    "a split), its novelty score and tuned threshold, and the one-shot nearest class means "
    "(app/baselines/common.py); they differ only in the zero-shot part (zsl, gzsl_unseen, "
    "gzsl_h)"
)

_KEPT_NOTE = (
    "nd_known_kept is the fit's own tuning figure, on held-out trials of its known training "
    "objects (Table II, X_te); nd_test_kept (--ceilings) and touches<k>_nd_known_kept count "
    "the known objects' test trials kept known at the same threshold (touches1_nd_known_kept "
    "is nd_test_kept), so they differ from it"
)


def _finite(v: Any) -> bool:
    return isinstance(v, int | float) and math.isfinite(v)


def _per_split(entry: dict[str, Any], figure: str) -> list[Any]:
    return [s.get(figure) for s in entry.get("splits", [])]


def _same(a: Sequence[Any], b: Sequence[Any]) -> bool:
    """Equal on every split: both finite and within rounding, or both unmeasured."""
    if len(a) != len(b):
        return False
    for x, y in zip(a, b, strict=True):
        if _finite(x) and _finite(y):
            if abs(x - y) > 1e-9:
                return False
        elif _finite(x) or _finite(y):
            return False
    return True


def fold_equal_rows(
    results: dict[str, Any], rows: Sequence[str]
) -> tuple[list[str], list[tuple[str, str, str]]]:
    """(the rows to print, the (row, equal row, why) left out): a row of
    ``EQUAL_BY_DEFINITION`` is left out where the row it equals is printed too and every
    method that measured it has the same value in both on every split."""
    shown = set(rows)
    folded = []
    for f in rows:
        if f not in EQUAL_BY_DEFINITION:
            continue
        g, why = EQUAL_BY_DEFINITION[f]
        if g not in shown:
            continue
        entries = [e for e in results["methods"].values() if any(map(_finite, _per_split(e, f)))]
        if entries and all(_same(_per_split(e, f), _per_split(e, g)) for e in entries):
            folded.append((f, g, why))
    gone = {f for f, _, _ in folded}
    return [f for f in rows if f not in gone], folded


def identical_rows(
    results: dict[str, Any], rows: Sequence[str]
) -> dict[tuple[str, ...], list[str]]:
    """{methods: rows}: the rows in which those methods (two or more) have the same value
    on every split, every split measured."""
    methods = list(results["methods"])
    out: dict[tuple[str, ...], list[str]] = {}
    for f in rows:
        left = [m for m in methods if all(map(_finite, _per_split(results["methods"][m], f)))]
        while left:
            head = left.pop(0)
            ref = _per_split(results["methods"][head], f)
            same = [m for m in left if _same(_per_split(results["methods"][m], f), ref)]
            if same:
                out.setdefault((head, *same), []).append(f)
            left = [m for m in left if m not in same]
    return out


def _forest_baselines(methods: Sequence[str]) -> bool:
    """Every method a forest baseline (``app.baselines.common.ForestBaseline``)."""
    from app.baselines.common import ForestBaseline
    from app.framework.registry import UnknownMethodError, method_class

    try:
        return all(issubclass(method_class(m), ForestBaseline) for m in methods)
    except UnknownMethodError:  # a method this install no longer knows (an old results.json)
        return False


def render(head: Sequence[str], body: Sequence[Sequence[str]]) -> list[str]:
    """A plain-text table: the first column left-aligned, the others right-aligned, each
    as wide as its widest cell (header included) plus two spaces between columns."""
    n = len(head)
    widths = [max(len(r[j]) for r in [head, *body]) for j in range(n)]
    lines = []
    for row in [head, *body]:
        cells = [row[0].ljust(widths[0])] + [row[j].rjust(widths[j]) for j in range(1, n)]
        lines.append("  ".join(cells).rstrip())
    return lines


def _cell(mean: Any, ci: Any = None, signed: bool = False) -> str:
    """``0.612 [0.590, 0.634]``; ``—`` for a figure not measured."""
    if not _finite(mean):
        return "—"
    fmt = "{:+.3f}" if signed else "{:.3f}"
    lo, hi = ci if ci else (None, None)
    if not (_finite(lo) and _finite(hi)):
        return fmt.format(mean)
    return f"{fmt.format(mean)} [{fmt.format(lo)}, {fmt.format(hi)}]"


def _lower_is_better(figure: str) -> bool:
    """The adaptive rule's robot time and procedures used (``adaptive<t>_time``,
    ``_time_known``, ``_time_novel``, ``_procedures``): less is better."""
    return re.fullmatch(r"adaptive\d+_(time(_known|_novel)?|procedures)", figure) is not None


def _rows(results: dict[str, Any]) -> list[str]:
    # only what was measured: a figure no method has a finite mean of gets no row of "—"
    present = set(measured_figures(results))
    # the mixed figures in the order seen, unseen, h
    mixed = {"seen": "0", "unseen": "1", "h": "2"}
    return [f for f in ORDER if f in present] + sorted(
        present - set(ORDER),
        key=lambda f: (
            f.startswith("ceil_"),
            re.sub(r"_(seen|unseen|h)$", lambda m: "_" + mixed[m.group(1)], f),
        ),
    )


def _measured_by(results: dict[str, Any], f: str) -> tuple[str, ...]:
    return tuple(m for m, e in results["methods"].items() if _finite(e["mean"].get(f)))


def _mean_rows(results: dict[str, Any], methods: Sequence[str], rows: Sequence[str]):
    for f in rows:
        cells = [f]
        for m in methods:
            e = results["methods"][m]
            cells.append(_cell(e["mean"].get(f), (e.get("ci95") or {}).get(f)))
        yield cells


def summary_table(results: dict[str, Any]) -> str:
    """Mean figures per method, each with its 95 % confidence interval over splits, each
    figure once (see the module's docstring), the timings with their units, and the notes
    that say what was left out and why; with several methods, each method's paired
    difference from the first (its 95 % interval, splits won / lost)."""
    if results.get("protocol") == PROTOCOL:
        return raw_summary_table(results)
    methods = list(results["methods"])
    rows, folded = fold_equal_rows(results, _rows(results))
    everyone = tuple(methods)
    main = [f for f in rows if _measured_by(results, f) == everyone]
    partial: dict[tuple[str, ...], list[str]] = {}
    for f in rows:
        if (by := _measured_by(results, f)) != everyone:
            partial.setdefault(by, []).append(f)

    body = list(_mean_rows(results, methods, main))
    n = results.get("splits")
    fit = []
    for m in methods:
        fits = [
            d["timings"]["fit_s"]
            for d in results["methods"][m].get("details", [])
            if _finite((d.get("timings") or {}).get("fit_s"))
        ]
        fit.append(f"{sum(fits) / len(fits):.1f}" if fits else "—")
    body.append(["fit_s_per_split", *fit])
    body.append(
        ["run_s_summed_over_splits"]
        + [f"{results['methods'][m].get('elapsed_s', math.nan):.1f}" for m in methods]
    )
    lines = render(["figure", *methods], body)
    lines.append(f"mean [95% CI]: Student's t over the {n} splits' values, clipped to [0, 1]")
    jobs, wall = results.get("jobs", 1), results.get("elapsed_s")
    side = (
        f"; the splits ran in {jobs} processes side by side, so these sums can exceed the "
        f"run's {wall:.1f} s of wall time"
        if jobs and jobs > 1 and _finite(wall)
        else ""
    )
    lines.append(
        "timings in seconds: fit_s_per_split, the mean over splits of one fit's seconds; "
        f"run_s_summed_over_splits, fitting and measuring, summed over the {n} splits" + side
    )
    for by, figs in partial.items():
        if not by:
            continue
        lines += [
            "",
            f"measured by {', '.join(by)} only" + _variant_note(figs),
            *render(["figure", *by], list(_mean_rows(results, by, figs))),
        ]
    lines += _notes(results, rows, folded)
    lines += rerun_lines(results, main)
    lines += paired_lines(results, rows)
    return "\n".join(lines)


def _variant_note(figures: Sequence[str]) -> str:
    if any(f in ("zsl_genf", "zsl_nogan") for f in figures):
        return (
            " (the paper pipeline's ZSL enrolments: GEN-F, Table V, and no GAN, Table VI; "
            "its NEIGHB-F is its zsl)"
        )
    return ""


def _notes(
    results: dict[str, Any], rows: Sequence[str], folded: Sequence[tuple[str, str, str]]
) -> list[str]:
    lines = []
    if folded:
        lines += ["", "not printed, equal on every split by definition:"]
        lines += [f"  {f} = {g} ({why})" for f, g, why in folded]
    kept = [f for f in rows if f == "nd_test_kept" or re.fullmatch(r"touches\d+_nd_known_kept", f)]
    if kept and "nd_known_kept" in rows:
        lines += ["", _KEPT_NOTE]
    for group, figs in identical_rows(results, rows).items():
        if len(group) < 2:
            continue
        lines += [
            "",
            f"{', '.join(group)}: identical on every split in {', '.join(figs)}",
        ]
        if _forest_baselines(group):
            lines.append(f"  {SHARED_PARTS}")
    return lines


def rerun_lines(results: dict[str, Any], rows: Sequence[str]) -> list[str]:
    """Where a re-run's mean lands, a row per figure that has the range (none in results that
    predate it, or of one split)."""
    methods = list(results["methods"])
    body = []
    for f in rows:
        cells = []
        for m in methods:
            lo, hi = (results["methods"][m].get("rerun95") or {}).get(f) or (None, None)
            cells.append(f"[{lo:.3f}, {hi:.3f}]" if _finite(lo) and _finite(hi) else "—")
        if any(c != "—" for c in cells):
            body.append([f, *cells])
    if not body:
        return []
    return [
        "",
        f"where a re-run of {results.get('rerun_splits')} splits on another seed lands (95%)",
        *render(["figure", *methods], body),
    ]


def paired_lines(results: dict[str, Any], rows: Sequence[str]) -> list[str]:
    """The paired differences from the reference method, a row per figure (none with one
    method), and the legend of won/lost."""
    paired = results.get("paired")
    if not paired or not paired.get("methods"):
        return []
    ref = paired["reference"]
    others = list(paired["methods"])
    body = []
    reversed_rows = False
    equal = []
    for f in rows:
        if all(not _finite(paired["methods"][m]["mean"].get(f)) for m in others):
            continue
        splits = [paired["methods"][m].get("splits", {}).get(f) for m in others]
        if all(d and all(v == 0 for v in d) for d in splits):
            equal.append(f)
            continue
        cells = [f]
        for m in others:
            p = paired["methods"][m]
            if not _finite(p["mean"].get(f)):
                cells.append("—")
                continue
            won, lost = p["won"][f], p["lost"][f]
            if _lower_is_better(f):  # results.json counts splits above / below
                won, lost = lost, won
                reversed_rows = True
            cell = _cell(p["mean"][f], p["ci95"].get(f), signed=True)
            cells.append(f"{cell} {won}/{lost}")
        body.append(cells)
    n = results.get("splits")
    pressure = any(r[0].startswith("pressure_") for r in body)
    repeats = " (for pressure_* rows, repeats)" if pressure else ""
    legend = (
        f"won/lost: of the {n} splits{repeats}, those on which the column's method beat {ref} / "
        f"{ref} beat it (a higher figure wins; ties count in neither)"
    )
    if reversed_rows:
        legend += "; in the adaptive rule's _time and _procedures rows the lower figure wins"
    lines = ["", f"paired difference from {ref} on the same splits: mean [95% CI] won/lost"]
    if body:
        lines += render(["figure", *(f"{m} - {ref}" for m in others)], body)
        lines.append(legend)
    if equal:
        lines.append(f"no difference from {ref} on any split, not printed: {', '.join(equal)}")
    return lines


def raw_summary_table(results: dict[str, Any]) -> str:
    """Raw-trial results: mean and 95 % confidence interval of every figure per method, the
    seconds each method ran, and with several methods the paired differences from the
    first."""
    methods = list(results["methods"])
    figures = raw_figures(results)
    body = list(_mean_rows(results, methods, figures))
    body.append(
        ["run_s_all_fits"]
        + [f"{results['methods'][m].get('elapsed_s', math.nan):.1f}" for m in methods]
    )
    lines = render(["figure", *methods], body)
    lines.append(
        "run_s_all_fits: seconds, every trial split's and held-out pressure's fits and "
        "answers of the method, one after another in one process"
    )
    lines += paired_lines(results, figures)
    return "\n".join(lines)
