"""bench/research/rerun_check.py's counting, on hand-made results whose answers are known:
a re-run inside or outside the published re-run range and confidence interval."""

from __future__ import annotations

import runpy
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "bench" / "research" / "rerun_check.py"


@pytest.fixture(scope="module")
def script() -> dict:
    return runpy.run_path(str(SCRIPT))


def _results(mean: float, ci95=None, rerun95=None) -> dict:
    entry = {"mean": {"zsl": mean}}
    if ci95 is not None:
        entry |= {"ci95": {"zsl": ci95}, "rerun95": {"zsl": rerun95}}
    return {"methods": {"best": entry}}


def test_counts_reruns_inside_each_interval(script):
    base = _results(0.50, ci95=[0.48, 0.52], rerun95=[0.46, 0.54])
    reruns = {11: _results(0.51), 12: _results(0.53), 13: _results(0.56)}
    row = script["check"](base, reruns)["best"]["zsl"]
    assert row["checked"] == 3
    assert row["inside_ci95"] == 1  # only 0.51
    assert row["inside_rerun95"] == 2  # 0.51 and 0.53; 0.56 lies outside both
    assert row["reruns"] == {"11": 0.51, "12": 0.53, "13": 0.56}
    # a figure the re-runs do not measure (a base run with --ceilings) is left out
    base["methods"]["best"]["mean"]["ceil_gzsl_h"] = 0.6
    assert list(script["check"](base, reruns)["best"]) == ["zsl"]
    del base["methods"]["best"]["mean"]["ceil_gzsl_h"]
    report = {
        "seeds": [11, 12, 13],
        "novel": 6,
        "base_splits": 500,
        "base_seed": 1000,
        "rerun_splits": 50,
        "methods": script["check"](base, reruns),
    }
    text = script["table"](report)
    assert "| `zsl` | 0.500 [0.480, 0.520] | [0.460, 0.540] | 0.510 | 0.530 | **0.560** |" in text
    assert "Inside the re-run range: 2 of 3; inside the confidence interval: 1 of 3." in text


def test_refuses_a_base_without_rerun_ranges_and_its_own_seed(script, tmp_path):
    old = tmp_path / "old.json"
    old.write_text('{"seed": 1000, "methods": {}}')
    with pytest.raises(SystemExit, match="no re-run ranges"):
        script["main"](["--base", str(old), "--seeds", "11"])
    own = tmp_path / "own.json"
    own.write_text('{"seed": 1000, "rerun_splits": 50, "novel": 6, "test_trials": 2}')
    with pytest.raises(SystemExit, match="seed 1000 is a published run's own"):
        script["main"](["--base", str(own), "--seeds", "11,1000"])


def test_refuses_bases_of_different_sizes(script, tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text('{"seed": 1000, "rerun_splits": 50, "novel": 6, "test_trials": 2}')
    b.write_text('{"seed": 1000, "rerun_splits": 50, "novel": 12, "test_trials": 2}')
    with pytest.raises(SystemExit, match="the bases differ in novel"):
        script["main"](["--base", str(a), "--base", str(b), "--seeds", "11"])
