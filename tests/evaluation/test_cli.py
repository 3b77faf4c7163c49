"""tactile-zsl evaluate: help text for every option, a small end-to-end run, clear errors."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from app.cli import main

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
