"""The table ``tactile-zsl evaluate`` prints says each figure once: rows equal to another by
definition are folded into a note, timings carry units, won/lost names the winner, every
value sits inside its column, and the forest baselines' shared figures are explained."""

from __future__ import annotations

import contextlib
import copy
import io
import json
import re

import pytest

from app.cli import main
from app.evaluation.summary import EQUAL_BY_DEFINITION, SHARED_PARTS, render, summary_table

ROW = re.compile(r"^[a-z][a-z0-9_]*  ")  # a row: a figure's name, then column padding
CELL = re.compile(r"\S+(?: \S+)*")  # a cell: words joined by single spaces


def tables(text: str) -> list[tuple[str, list[str]]]:
    """(header, rows) of every table printed in ``text``: a header starts with "figure",
    the rows right below it each start with a name followed by padding."""
    out: list[tuple[str, list[str]]] = []
    open_table = False
    for line in text.splitlines():
        if line.startswith("figure  "):
            out.append((line, []))
            open_table = True
        elif open_table and ROW.match(line):
            out[-1][1].append(line)
        else:
            open_table = False
    return out


def misaligned(header: str, row: str) -> str | None:
    """Why ``row`` does not sit in ``header``'s columns (first column left-aligned, the
    others right-aligned under their names), or None."""
    heads = [m.span() for m in CELL.finditer(header)]
    cells = [m.span() for m in CELL.finditer(row)]
    if len(cells) != len(heads):
        return f"{len(cells)} cells under {len(heads)} columns"
    if cells[0][0] != 0:
        return "the name does not start the line"
    for j in range(1, len(heads)):
        left = max(heads[j - 1][1], cells[j - 1][1])
        if cells[j][1] != heads[j][1] or cells[j][0] <= left or heads[j][0] <= cells[j - 1][1]:
            return f"cell {j} at {cells[j]} against its column {heads[j]}"
    return None


def values(rows: list[str]) -> dict[str, list[str]]:
    return {r.split()[0]: [m.group() for m in CELL.finditer(r)][1:] for r in rows}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A small run of the three forest baselines with --ceilings and --touches 1."""
    out = tmp_path_factory.mktemp("printed") / "r.json"
    args = ["evaluate", "--dataset", "simulated:14", "--novel", "3", "--splits", "2"]
    args += ["--seed", "1", "--methods", "eszsl,dap,extratrees", "--ceilings", "--touches", "1"]
    args += ["--jobs", "1", "--out", str(out), "--no-progress"]
    for m in ("eszsl", "dap", "extratrees"):
        args += ["--param", f"{m}.n_estimators=20"]
    args += ["--param", "extratrees.attribute_estimators=20"]
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(args) == 0
    return json.loads(out.read_text()), printed.getvalue()


def test_rows_equal_by_definition_are_folded_into_a_note(run):
    results, printed = run
    (header, rows), *_ = tables(printed)
    shown = values(rows)
    # the results keep every figure; the table prints each once
    mean = results["methods"]["dap"]["mean"]
    for f in ("ceil_gzsl_seen", "ceil_gzsl_unseen", "osl_gzsl_seen", "touches1_zsl"):
        assert f in mean
    for f, (g, _) in EQUAL_BY_DEFINITION.items():
        if f in shown and g in shown:
            assert shown[f] != shown[g], f"{f} repeats {g}"
    # the simulator has one sample per trial: every touches1 row equals its base row
    folded = [f for f in EQUAL_BY_DEFINITION if f in mean and EQUAL_BY_DEFINITION[f][0] in mean]
    assert "touches1_nd_known_kept" in folded and "ceil_gzsl_seen" in folded
    for f in folded:
        assert f not in shown
        assert f"  {f} = {EQUAL_BY_DEFINITION[f][0]} (" in printed
    # what the table does print is measured
    for f in shown:
        assert f in mean or "_s_" in f


def test_the_differing_kept_row_is_explained(run):
    """Without --ceilings there is no nd_test_kept for touches1_nd_known_kept to fold into:
    it is printed, with why it differs from nd_known_kept."""
    results, _ = run
    res = copy.deepcopy(results)
    for entry in res["methods"].values():
        for part in [
            entry["mean"],
            entry["std"],
            entry["ci95"],
            entry["rerun95"],
            *entry["splits"],
        ]:
            part.pop("nd_test_kept", None)
    for p in res["paired"]["methods"].values():
        for part in p.values():
            part.pop("nd_test_kept", None)
    text = summary_table(res)
    assert "touches1_nd_known_kept" in values(tables(text)[0][1])
    note = "touches<k>_nd_known_kept count the known objects' test trials kept known"
    assert note in text and "so they differ from it" in text
    # with --ceilings the folded row's twin, nd_test_kept, gets the same explanation
    assert note in run[1] and "nd_test_kept" in values(tables(run[1])[0][1])


def test_timings_have_units(run):
    results, printed = run
    (header, rows), *_ = tables(printed)
    timing = [f for f in values(rows) if f not in results["methods"]["dap"]["mean"]]
    assert timing == ["fit_s_per_split", "run_s_summed_over_splits"]
    assert "seconds" not in values(rows)
    note = next(line for line in printed.splitlines() if line.startswith("timings in seconds"))
    assert all(f in note for f in timing) and "summed over the 2 splits" in note
    summed = values(rows)["run_s_summed_over_splits"]
    assert summed == [f"{results['methods'][m]['elapsed_s']:.1f}" for m in results["methods"]]


def test_won_lost_names_the_winner(run):
    results, printed = run
    legend = [line for line in printed.splitlines() if line.startswith("won/lost:")]
    assert len(legend) == 1
    assert "the column's method beat eszsl / eszsl beat it" in legend[0]
    header, rows = tables(printed)[-1]
    assert "dap - eszsl" in header and "extratrees - eszsl" in header
    # figures with no difference on any split are named, not printed as rows of +0.000 0/0
    left_out = next(x for x in printed.splitlines() if x.startswith("no difference from eszsl"))
    assert "known_acc" in left_out.split(": ")[1].split(", ")
    assert "known_acc" not in values(rows) and "gzsl_h" in values(rows)
    # the counts printed are results.json's splits above / below
    p = results["paired"]["methods"]["dap"]
    for f, cells in values(rows).items():
        if cells[0] != "—":
            assert cells[0].endswith(f" {p['won'][f]}/{p['lost'][f]}")


def test_every_value_lies_inside_its_column(run):
    _, printed = run
    found = tables(printed)
    assert len(found) >= 2  # the means and the paired differences
    for header, rows in found:
        assert rows
        for row in rows:
            assert misaligned(header, row) is None, (header, row, misaligned(header, row))


def test_render_widens_columns_to_their_longest_name():
    long = "touches12_nd_novel_detected_by_a_long_name"
    lines = render(["figure", "m"], [[long, "0.612 [0.590, 0.634]"], ["zsl", "0.1"]])
    assert all(misaligned(lines[0], row) is None for row in lines[1:])
    assert misaligned("figure     m", "touches1_zsl0.5") is not None  # the check can fail


def test_baselines_shared_figures_are_explained(run):
    results, printed = run
    line = next(x for x in printed.splitlines() if ": identical on every split in " in x)
    group, rows = line.split(": identical on every split in ")
    assert group == "eszsl, dap, extratrees"
    same = rows.split(", ")
    # the shared known-class forest and novelty detector, and the one-shot class means
    for f in ("known_acc", "nd_known_kept", "nd_auroc", "gzsl_seen", "osl", "ceil_nd_balance"):
        assert f in same
        per = [[s[f] for s in results["methods"][m]["splits"]] for m in results["methods"]]
        assert per[0] == per[1] == per[2]
    assert SHARED_PARTS in printed
    # the zero-shot parts differ: somewhere the methods do not agree
    zsl = {m: [s["zsl"] for s in e["splits"]] for m, e in results["methods"].items()}
    assert len({tuple(v) for v in zsl.values()}) > 1 or "zsl" in same


def test_figures_of_some_methods_get_a_section_of_their_own(run):
    """A figure only one method measures (as the paper pipeline's ZSL variants) prints in a
    table with that method's column only, not as a row of "—"."""
    results, _ = run
    res = copy.deepcopy(results)
    entry = res["methods"]["dap"]
    entry["mean"]["zsl_genf"], entry["ci95"]["zsl_genf"] = 0.5, [0.4, 0.6]
    for s in entry["splits"]:
        s["zsl_genf"] = 0.5
    text = summary_table(res)
    found = tables(text)
    assert "zsl_genf" not in values(found[0][1])
    header, rows = next((h, r) for h, r in found if "zsl_genf" in values(r))
    assert header.split() == ["figure", "dap"] and values(rows)["zsl_genf"] == [
        "0.500 [0.400, 0.600]"
    ]
    assert "measured by dap only" in text


def test_raw_trial_table_has_units_legend_and_aligned_columns(tmp_path):
    """The raw-trial protocol's table on the BioTac pilot: the same rules."""
    from tests.framework.raw_data import pilot_path

    out = tmp_path / "raw.json"
    args = ["evaluate", "--dataset", f"biotac:{pilot_path()}", "--splits", "2"]
    args += ["--methods", "extratrees,dap", "--out", str(out), "--no-progress"]
    # forests of different sizes: the two differ (with equal ones they are one forest)
    args += ["--param", "extratrees.n_estimators=20", "--param", "dap.n_estimators=7"]
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(args) == 0
    text = printed.getvalue()
    results = json.loads(out.read_text())
    found = tables(text)
    assert found
    for header, rows in found:
        for row in rows:
            assert misaligned(header, row) is None, (header, row)
    shown = values(found[0][1])
    assert "seconds" not in shown and "run_s_all_fits" in shown
    assert "run_s_all_fits: seconds," in text
    assert [f for f in shown if f not in results["methods"]["dap"]["mean"]] == ["run_s_all_fits"]
    assert "won/lost: of the 2 splits (for pressure_* rows, repeats), those on which the " in text


def test_only_the_forest_baselines_get_the_shared_parts_reason(run):
    """Methods that are not forest baselines (here unknown names) get the fact, not the
    baselines' reason."""
    results, _ = run
    res = copy.deepcopy(results)
    res["methods"] = {f"{m}-renamed": e for m, e in res["methods"].items()}
    res.pop("paired")
    text = summary_table(res)
    assert "eszsl-renamed, dap-renamed, extratrees-renamed: identical on every split in" in text
    assert SHARED_PARTS not in text
