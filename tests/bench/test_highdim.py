"""bench/highdim.py at a tiny size: both methods on every seed, each in a process of its own,
the JSON and the PNG, and clear refusals of bad arguments. The figures mean nothing at this
size."""

from __future__ import annotations

import functools
import json

import pytest

from tests.bench import run_bench

run = functools.partial(run_bench, "bench.highdim")


def test_a_tiny_run_measures_both_methods_on_the_same_touches(tmp_path):
    done = run("--objects", "6", "--trials", "3", "--channels", "40", "--steps", "30",
               "--seeds", "1", "--out", str(tmp_path))  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads((tmp_path / "highdim.json").read_text())
    runs = report["runs"]
    assert [r["method"] for r in runs] == ["auto", "extratrees"]
    for r in runs:
        # 6 objects x 2 training trials of 40 x 30 = 1,200 values: wide enough to reduce
        assert r["n_train"] == 12 and r["n_features"] == 1200
        assert 0.0 <= r["known_acc"] <= 1.0
        assert r["fit_s"] > 0 and r["peak_rss_gb"] >= r["rss_before_gb"] > 0
    assert runs[0]["chosen"] in ("prototypes", "best") and runs[0]["probe_s"] is not None
    assert set(report["summary"]) == {"auto", "extratrees", "auto_over_extratrees"}
    assert report["machine"]["commit"] and "cpu_model" in report["machine"]
    assert (tmp_path / "highdim.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    "args, message",
    [
        (("--channels", "30"), "--channels must be a positive multiple of 4"),
        (("--seeds", "a,b"), "--seeds must be integers"),
        (("--trials", "2"), "--objects and --trials must be at least 3"),
    ],
)
def test_bad_arguments_are_refused_with_their_names(args, message):
    done = run(*args)
    assert done.returncode == 2 and message in done.stderr, done.stderr[-2000:]
