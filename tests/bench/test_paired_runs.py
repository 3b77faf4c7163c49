"""bench/paired_runs.py pairs one method's figures across two evaluate runs of one split set."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from app.cli import main as cli
from bench.paired_runs import main, paired_table


def evaluate(phac2: Path, out: Path, seed: int) -> dict:
    args = ["--dataset", f"phac2:{phac2}", "--novel", "6", "--splits", "2", "--seed", str(seed)]
    assert cli(["evaluate", *args, "--methods", "best", "--jobs", "1", "--out", str(out)]) == 0
    return json.loads(out.read_text())


@pytest.mark.phac2
def test_the_same_run_twice_differs_by_nothing_and_other_splits_are_refused(
    phac2_path, tmp_path, capsys
):
    a = evaluate(phac2_path, tmp_path / "a.json", 5)
    b = evaluate(phac2_path, tmp_path / "b.json", 5)
    rows = paired_table(a, b, "best")
    assert {r["figure"] for r in rows} >= {"known_acc", "zsl", "gzsl_h", "nd_auroc"}
    for r in rows:
        assert r["before"] == r["after"] and r["difference"] == 0.0 and r["holds_zero"]
    capsys.readouterr()  # what evaluate printed
    assert main([str(tmp_path / "a.json"), str(tmp_path / "b.json")]) == 0
    assert capsys.readouterr().out.startswith("| figure | before | after |")
    evaluate(phac2_path, tmp_path / "c.json", 6)
    capsys.readouterr()
    assert main([str(tmp_path / "a.json"), str(tmp_path / "c.json")]) == 2
    assert "different splits" in capsys.readouterr().err
    assert main([str(tmp_path / "a.json"), str(tmp_path / "missing.json")]) == 2
