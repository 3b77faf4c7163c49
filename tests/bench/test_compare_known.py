"""bench/compare_known.py at tiny sizes: every candidate on every data set, the table, the
PNG, and clear refusals of bad arguments. The figures mean nothing at this size."""

from __future__ import annotations

import functools
import json

import pytest

from tests.bench import run_bench

run = functools.partial(run_bench, "bench.compare_known")


def test_tiny_sizes_score_every_candidate_on_the_same_splits(tmp_path):
    done = run("--sizes", "12", "--folds", "0", "--candidates", "prototypes,lda,nn1,cosface",
               "--out", str(tmp_path))  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads((tmp_path / "compare_known.json").read_text())
    assert set(report["results"]) == {"sim-12", "sim-12-modes3"}
    for row in report["results"].values():
        assert set(row) == {"prototypes", "lda", "nn1", "cosface"}
        for figures in row.values():
            assert 0.0 <= figures["acc"] <= 1.0 and len(figures["folds"]) == 1
    assert report["machine"]["commit"]
    assert done.stdout.startswith("| data set | prototypes | lda | nn1 | cosface |")
    assert (tmp_path / "compare_known.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.phac2
def test_phac2s_trial_folds_hold_out_each_trial_once(phac2_path, tmp_path):
    done = run("--sizes", "12", "--folds", "2", "--candidates", "lda,nn1",
               "--out", str(tmp_path))  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads((tmp_path / "compare_known.json").read_text())
    for figures in report["results"]["phac2"].values():
        assert len(figures["folds"]) == 2 and 0.1 <= figures["acc"] <= 1.0  # chance: 1/60


def test_bad_arguments_exit_2_with_a_message(tmp_path):
    for args, words in (
        (("--sizes", "1"), "at least 2 objects"),
        (("--sizes", "x"), "--sizes must be integers"),
        (("--candidates", "forest"), "--candidates takes some of"),
        (("--folds", "1"), "--folds must be 0 or at least 2"),
    ):
        done = run(*args, "--out", str(tmp_path))
        assert done.returncode == 2 and words in done.stderr, (args, done.stderr)
