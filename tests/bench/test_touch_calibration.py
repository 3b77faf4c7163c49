"""bench/touch_calibration.py end to end on a tiny simulated split set: known objects kept
and unseen ones detected at 1 and 3 touches, by the single touches' threshold and by the
curve of as many touches, the same at one touch, and clear refusals of bad arguments."""

from __future__ import annotations

import functools
import json

from tests.bench import run_bench

run = functools.partial(run_bench, "bench.touch_calibration", timeout=600)


def test_fused_answers_are_measured_by_both_curves(tmp_path):
    done = run("--dataset", "simulated:40", "--novel", "4", "--splits", "2", "--seed", "3",
               "--touches", "1,3", "--out", str(tmp_path))  # fmt: skip
    assert done.returncode == 0, done.stderr[-4000:]
    report = json.loads((tmp_path / "touch_calibration.json").read_text())
    assert report["splits"] == 2 and report["touches"] == [1, 3]
    rows = {(r["objects"], r["touches"]): r for r in report["summary"]}
    assert sorted(rows) == [("known", 1), ("known", 3), ("novel", 1), ("novel", 3)]
    for (_, k), r in rows.items():
        for key in ("before", "after"):
            assert 0 <= r[key]["low"] <= r[key]["mean"] <= r[key]["high"] <= 1
        if k == 1:  # one touch: the single touches' curve either way
            assert r["before"] == r["after"] and r["calibrated_touches"] == [1]
    assert "| known kept | 3 |" in done.stdout


def test_bad_arguments_exit_2_with_a_message(tmp_path):
    for args, words in (
        (("--touches", "0,3"), "touch counts must be positive"),
        (("--known-kept", "1.5"), "--known-kept must lie in (0, 1)"),
        (("--splits", "1"), "--splits must be at least 2"),
        (("--method", "nothing"), "not one of"),
    ):
        done = run(*args, "--out", str(tmp_path), timeout=120)
        assert done.returncode == 2 and words in done.stderr, (args, done.stderr)
