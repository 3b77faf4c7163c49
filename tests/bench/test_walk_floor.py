"""bench/walk_floor.py at tiny sizes: a record per size with positive times, the JSON, and a
clear refusal of bad sizes. The figures mean nothing at this size."""

from __future__ import annotations

import functools
import json

from tests.bench import run_bench

run = functools.partial(run_bench, "bench.walk_floor")


def test_tiny_sizes_give_a_record_each_and_a_table(tmp_path):
    done = run("--sizes", "12,6", "--repeats", "5", "--rounds", "1", "--out", str(tmp_path))
    assert done.returncode == 0, done.stderr
    records = json.loads((tmp_path / "walk_floor.json").read_text())["sizes"]
    assert [r["objects"] for r in records] == [6, 12]  # smallest first: the base
    for r in records:
        assert r["forest_nodes"] > 0 and 0 < r["walk_us"] and 0 < r["answer_us"]
        assert 0 < r["general_us"] and r["search_us"] == 0.0  # exact below 20,000 samples
    assert "| 12 |" in done.stdout and "answer ÷ at 6" in done.stdout
    assert (tmp_path / "walk_floor.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_model_with_an_index_times_its_search(tmp_path):
    done = run(
        "--sizes", "12", "--repeats", "5", "--rounds", "1",
        "--approximate-above", "50", "--out", str(tmp_path),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    (record,) = json.loads((tmp_path / "walk_floor.json").read_text())["sizes"]
    assert record["search_us"] > 0 and record["answer_us"] > 0


def test_bad_sizes_are_refused():
    done = run("--sizes", "60,lots")
    assert done.returncode == 2 and "--sizes must be integers" in done.stderr
    done = run("--sizes", "1")
    assert done.returncode == 2 and "2 objects" in done.stderr
    done = run("--approximate-above", "-1")
    assert done.returncode == 2 and "--approximate-above must be 0 or more" in done.stderr
