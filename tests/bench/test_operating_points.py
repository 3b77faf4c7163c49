"""bench/operating_points.py end to end on a tiny simulated split set: every stated share
measured on held-out trials and unseen objects, a higher share keeping at least as many
known trials, the figures drawn, and clear refusals of bad arguments."""

from __future__ import annotations

import functools
import json

from app.data.sources import load_dataset
from app.evaluation.splits import make_zsl_splits
from tests.bench import run_bench
from tests.kept_share import assert_keeps

run = functools.partial(run_bench, "bench.operating_points", timeout=600)


def test_each_stated_share_is_measured_on_trials_and_objects_it_never_saw(tmp_path):
    done = run("--dataset", "simulated:30", "--novel", "4", "--splits", "2", "--seed", "3",
               "--method", "prototypes", "--shares", "0.5,0.99",
               "--out", str(tmp_path))  # fmt: skip
    assert done.returncode == 0, done.stderr[-4000:]
    report = json.loads((tmp_path / "operating_points.json").read_text())
    assert report["splits"] == 2 and report["shares"] == [0.5, 0.99]
    assert [f["share"] for f in report["summary"]] == [None, 0.5, 0.99]
    for split in report["per_split"]:
        own, half, most = split["points"]
        assert half["kept"] <= most["kept"] and half["detected"] >= most["detected"]
        for figures in (own, half, most):
            assert 0 <= figures["kept"] <= 1 and 0 <= figures["detected"] <= 1
    kept = report["summary"][2]["kept"]
    assert kept["low"] <= kept["mean"] <= kept["high"]
    # each stated share, over both splits' held-out known touches (equal counts: the mean
    # is the pooled share), within 3 binomial sigmas and the curve's resolution: the probe
    # holds out one trial, one sample, of each known object, so its curve steps by one of
    # them (0.35 kept for 0.5 and 1.0 for 0.99 measured on 2026-11-28)
    dataset = load_dataset("simulated:30")
    splits = make_zsl_splits(dataset, 4, 2, 3)
    n = sum(len(s.known_test_idx) for s in splits)
    resolution = 1 / (dataset.n_classes - 4)
    for stated, figures in zip((0.9, 0.5, 0.99), report["summary"], strict=True):
        assert_keeps(figures["kept"]["mean"], stated, n, resolution)
    assert (tmp_path / "operating_points.png").read_bytes()[:4] == b"\x89PNG"
    assert "| 0.99 |" in done.stdout


def test_bad_arguments_exit_2_with_a_message(tmp_path):
    for args, words in (
        (("--shares", "0.5,1.2"), "every share must lie in (0, 1)"),
        (("--shares", "half"), "not a list of numbers"),
        (("--splits", "1"), "--splits must be at least 2"),
        (("--method", "nothing"), "not one of"),
        (("--dataset", "simulated:0"), "object count must be a positive integer"),
    ):
        done = run(*args, "--out", str(tmp_path), timeout=120)
        assert done.returncode == 2 and words in done.stderr, (args, done.stderr)
