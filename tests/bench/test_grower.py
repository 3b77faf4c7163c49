"""bench/grower.py at a tiny size: a record for all features and for one procedure, both
growers timed and scored, the JSON, and a clear refusal of a bad size. The figures mean
nothing at this size."""

from __future__ import annotations

import functools
import json

from tests.bench import run_bench

run = functools.partial(run_bench, "bench.grower")


def test_a_tiny_run_times_both_growers_on_both_blocks(tmp_path):
    done = run(
        "--objects", "8", "--trees", "2", "--rounds", "1", "--small-nodes", "0,3",
        "--out", str(tmp_path),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    records = json.loads((tmp_path / "grower.json").read_text())["records"]
    assert [r["features"] for r in records][0] == "all" and len(records) == 2
    assert records[0]["dims"] == 4 * records[1]["dims"]  # one of the 4 procedures
    for r in records:
        assert r["gini_s"] > 0 and r["sklearn_s"] > 0
        assert 0 <= r["gini_acc"] <= 1 and 0 <= r["sklearn_acc"] <= 1
        assert set(r["gini_by_small_node_s"]) == {"0", "3"}
        assert min(r["gini_by_small_node_s"].values()) > 0
    assert "sklearn ÷ gini" in done.stdout and "| all (" in done.stdout
    assert "small_node 3" in done.stdout


def test_a_bad_size_is_refused():
    done = run("--objects", "1")
    assert done.returncode == 2 and "--objects must be 2 at least" in done.stderr
    done = run("--small-nodes", "64,lots")
    assert done.returncode == 2 and "--small-nodes must be integers" in done.stderr
