"""tactile-zsl evaluate: help text for every option, a small end-to-end run, clear errors."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from app.cli import main
from app.cli.evaluate import summary_table
from tests.evaluation.tables import (
    empty_definitions,
    empty_markdown_columns,
    empty_markdown_rows,
    empty_printed_rows,
)

OPTIONS = [
    "--dataset",
    "--novel",
    "--splits",
    "--seed",
    "--methods",
    "--out",
    "--report",
    "--test-trials",
    "--distinct-from-known",
    "--data-seed",
    "--jobs",
    "--ceilings",
    "--no-progress",
]


def test_help_lists_every_option():
    code = "import sys; from app.cli import main; sys.exit(main())"
    proc = subprocess.run(
        [sys.executable, "-c", code, "evaluate", "--help"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    text = proc.stdout
    for option in OPTIONS:
        assert option in text, option
    for name in ("paper", "dap", "eszsl", "extratrees"):
        assert name in text
    # every option has its own help text (argparse prints "--opt VALUE  text" or an indented line)
    from app.cli import build_parser

    sub = next(a for a in build_parser()._actions if a.dest == "command")
    for action in sub.choices["evaluate"]._actions:
        assert action.help, action.option_strings


def test_small_run_writes_results_and_report(tmp_path, capsys):
    out = tmp_path / "r.json"
    code = main(
        [
            "evaluate",
            "--dataset",
            "simulated:14",
            "--novel",
            "3",
            "--splits",
            "1",
            "--seed",
            "2",
            "--methods",
            "eszsl",
            "--out",
            str(out),
            "--report",
            str(tmp_path / "rep"),
            "--test-trials",
            "2",
            "--no-progress",
        ]
    )
    assert code == 0
    res = json.loads(out.read_text())
    assert res["dataset"] == "simulated:14" and res["novel"] == 3 and res["seed"] == 2
    assert res["splits"] == 1 and list(res["methods"]) == ["eszsl"]
    assert len(res["methods"]["eszsl"]["splits"]) == 1
    assert (tmp_path / "rep" / "report.md").stat().st_size > 0
    printed = capsys.readouterr().out
    assert "known_acc" in printed and "eszsl" in printed
    # only what was measured: no procedure figures without --procedures (the simulator names
    # four procedures), and of one split no re-run range, so no table of "—"
    assert not [f for f in res["methods"]["eszsl"]["mean"] if f.startswith(("procs", "adapt"))]
    assert empty_printed_rows(printed) == [] and "re-run" not in printed
    md = (tmp_path / "rep" / "report.md").read_text()
    assert empty_markdown_rows(md) == [] and empty_markdown_columns(md) == []
    assert empty_definitions(md) == [] and "- `gzsl_h`: harmonic mean" in md
    # the report opens with the figures: the first table after the title is the means
    assert md.split("\n")[2] == "## Mean figures" and "| `known_acc` |" in md.split("## ")[1]


def test_figures_never_measured_get_no_rows(tmp_path, capsys):
    """A results.json with figures of NaN only (as runs before 2026-11-28 summarised the
    procedure figures without --procedures): table and report leave them out."""
    from app.evaluation.report import write_report_from_file

    out = tmp_path / "r.json"
    args = ["evaluate", "--dataset", "simulated:14", "--novel", "3", "--splits", "2"]
    args += ["--seed", "1", "--methods", "eszsl,dap", "--out", str(out), "--no-progress"]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert empty_printed_rows(printed) == [] and "dap - eszsl" in printed
    res = json.loads(out.read_text())
    for entry in res["methods"].values():
        for key in ("mean", "std"):
            entry[key]["procs1000_known_acc"] = math.nan
        entry["ci95"]["procs1000_known_acc"] = entry["rerun95"]["procs1000_known_acc"] = [
            math.nan,
            math.nan,
        ]
        for split in entry["splits"]:
            split["procs1000_known_acc"] = math.nan
    assert "procs1000" not in summary_table(res)
    assert empty_printed_rows(summary_table(res)) == []
    saved = tmp_path / "old.json"
    saved.write_text(json.dumps(res))
    md = write_report_from_file(saved, tmp_path / "rep")[0].read_text()
    assert "procs1000" not in md and empty_markdown_rows(md) == []
    assert empty_markdown_columns(md) == [] and empty_definitions(md) == []
    assert "| `gzsl_h` |" in md and "## Paired differences from `eszsl`" in md


def test_errors_are_clear(tmp_path, capsys):
    code = main(
        [
            "evaluate",
            "--dataset",
            "simulated:14",
            "--methods",
            "nope",
            "--out",
            str(tmp_path / "r.json"),
            "--no-progress",
        ]
    )
    assert code == 2
    assert "unknown method 'nope'" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["evaluate", "--novel", "0"])
    assert exc.value.code == 2
