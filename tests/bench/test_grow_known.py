"""bench/grow_known.py: a small run prints every figure; bad arguments exit 2."""

import json

import pytest

from bench import grow_known


def test_a_small_run_reports_both_models_per_seed(tmp_path, capsys):
    out = tmp_path / "g.json"
    args = ["--seeds", "1", "--objects", "12", "--promoted", "2", "--trees", "5"]
    assert grow_known.main([*args, "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    row = report["seeds"][0]
    assert row["same_classes"] and row["grown_samples"] == 2 * grow_known.TRAIN_TRIALS
    for figure in ("grown_all", "full_all", "grown_promoted", "full_promoted"):
        assert 0.0 <= row[figure] <= 1.0 and report["mean"][figure] == row[figure]
    assert "| mean |" in capsys.readouterr().out


def test_bad_arguments_exit_2():
    with pytest.raises(SystemExit) as done:
        grow_known.main(["--promoted", "39"])
    assert done.value.code == 2
