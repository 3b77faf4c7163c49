"""bench/serve_ready.py end to end at a tiny size: a real ``serve`` that fits its default
method on first start, becomes ready, answers recognitions, and has each of its processes'
memory read from ``/proc``; and clear refusals of bad arguments. The times themselves mean
nothing at this size."""

from __future__ import annotations

import functools
import json

import pytest

from tests.bench import run_bench

run = functools.partial(run_bench, "bench.serve_ready", timeout=600)


@pytest.mark.slow
def test_a_tiny_service_fits_its_default_and_reports_each_process(tmp_path):
    done = run("--dataset", "simulated:40", "--recognise", "5", "--out", str(tmp_path))
    assert done.returncode == 0, done.stderr[-4000:]
    report = json.loads((tmp_path / "serve_ready.json").read_text())
    assert report["dataset"] == "simulated:40" and report["machine"]["commit"]
    assert 0 < report["ready_s"] < 600
    # the default method fitted on first start, its choice kept with the model
    assert report["model"]["method"] in ("best", "prototypes")
    assert report["model"]["chosen_by"]["method"] == report["model"]["method"]
    assert report["model"]["classes"] == 40
    roles = [p["role"] for p in report["processes"]]
    assert roles[0] == "serve (bootstrap, then supervisor)"
    assert roles.count("API") == report["api_processes"] >= 1
    for p in report["processes"]:
        assert 0 < p["Pss"] <= p["VmRSS"] * 1.01 and p["VmRSS"] <= p["VmHWM"], p
    serve = report["processes"][0]
    assert serve["VmHWM"] > serve["VmRSS"]  # the bootstrap's fit was its peak, since freed
    r = report["recognise_1_ms"]
    assert 0 < r["median"] <= r["p90"] <= r["worst"]
    assert report["met"]["ready_s"] and report["met"]["api_process_gb"]
    assert "| ready after |" in done.stdout and (tmp_path / "serve.log").is_file()
    assert (tmp_path / "serve_ready.png").read_bytes()[:4] == b"\x89PNG"


def test_bad_arguments_exit_2_with_a_message(tmp_path):
    for args, words in (
        (("--dataset", "simulated:0"), "object count must be a positive integer"),
        (("--dataset", "nothing"), "unknown dataset kind"),
        (("--processes", "0"), "--processes must be at least 1"),
        (("--recognise", "0"), "--recognise must be at least 1"),
    ):
        done = run(*args, "--out", str(tmp_path), timeout=60)
        assert done.returncode == 2 and words in done.stderr, (args, done.stderr)
