"""bench/scale_service.py end to end at a tiny size: a real ``serve`` on a fitted bundle,
every enrolment's job succeeded, the promoted class known, every figure positive, the
bundle reused with ``--model`` (and refused for other objects), the service's memory
watched, and clear refusals of bad arguments. The times themselves
mean nothing at this size."""

from __future__ import annotations

import functools
import json

import pytest

from tests.bench import run_bench

run = functools.partial(run_bench, "bench.scale_service", timeout=600)


@pytest.mark.slow
def test_a_tiny_service_measures_every_enrolment_and_reuses_its_bundle(tmp_path):
    done = run("--objects", "60", "--novel", "6", "--repeats", "2", "--recognise", "10",
               "--out", str(tmp_path))  # fmt: skip
    assert done.returncode == 0, done.stderr[-4000:]
    report = json.loads((tmp_path / "scale_service.json").read_text())
    assert report["objects"] == 60 and report["free_novel"] >= 2
    assert report["api_processes"] >= 1 and report["startup_s"] > 0
    assert report["machine"]["commit"] and len(report["load_average"]["start"]) == 3
    assert len(report["repeats"]) == 2
    for r in report["repeats"]:
        assert r["promoted_kind"] == "known" and r["promotion_reason"] == "promotion"
        assert r["grown_samples_added"] == report["promotion_threshold"]  # grown, not refitted
        for fig in ("register", "one_shot", "promote"):
            assert 0 < r[f"{fig}_live_s"] <= r[f"{fig}_everywhere_s"]
            assert r[f"{fig}_post_ms"] > 0
    s = report["summary"]
    for name, figure in s.items():
        assert 0 < figure["median"] <= figure["worst"], name
    assert s["recognise_1_ms"]["median"] <= s["recognise_1_ms"]["p90"]
    # the service's processes (serve and its API processes) watched for memory
    memory = report["memory"]
    assert len(memory["after_start_gb"]) >= 1 + report["api_processes"]
    assert 0 < min(memory["after_start_gb"]) and memory["peak_total_gb"] > 0
    assert 1 < memory["least_available_gb"] and not memory["stopped_for_memory"]
    assert "resident memory of its processes" in done.stdout
    assert_in_process(report["in_process"], 2)
    assert "| register |" in done.stdout and "| promote |" in done.stdout
    bundle = tmp_path / "best-60-6-0.bundle"
    assert bundle.is_file() and (tmp_path / "serve.log").is_file()

    again = run("--objects", "60", "--novel", "6", "--repeats", "1", "--recognise", "2",
                "--model", str(bundle), "--out", str(tmp_path / "again"))  # fmt: skip
    assert again.returncode == 0, again.stderr[-4000:]
    assert "fitting" not in again.stderr
    assert json.loads((tmp_path / "again" / "scale_service.json").read_text())["model"] == str(
        bundle
    )
    other = run("--objects", "50", "--novel", "6", "--model", str(bundle), "--out", str(tmp_path))
    assert other.returncode == 1 and "its known classes differ" in other.stderr, other.stderr


def assert_in_process(figures: dict, repeats: int) -> None:
    assert figures["load_s"] > 0 and figures["first_one_shot_s"] > 0
    assert figures["encode_base_s"] > 0 and figures["store_load_base_s"] > 0
    assert len(figures["repeats"]) == repeats
    for fig in ("register_s", "one_shot_s", "promote_s", "promote_encode_s", "promote_new_mb",
                "load_promoted_s"):  # fmt: skip
        assert 0 < figures[fig]["median"] <= figures[fig]["worst"], fig
        assert all(r[fig] > 0 for r in figures["repeats"]), fig


def test_in_process_only_measures_the_method_and_starts_no_service(tmp_path):
    done = run("--objects", "30", "--novel", "6", "--repeats", "2", "--in-process-only",
               "--out", str(tmp_path))  # fmt: skip
    assert done.returncode == 0, done.stderr[-4000:]
    report = json.loads((tmp_path / "scale_service.json").read_text())
    assert_in_process(report["in_process"], 2)
    assert "startup_s" not in report and "starting tactile-zsl serve" not in done.stderr
    assert "| promote |" in done.stdout and "first one-shot" in done.stdout
    assert "| promote_new | " in done.stdout and "| load_promoted | " in done.stdout
    assert "a reader's first load from the store" in done.stdout


def test_bad_arguments_exit_2_with_a_message(tmp_path):
    for args, words in (
        (("--objects", "1"), "--objects must be at least 2"),
        (("--repeats", "3", "--novel", "2"), "--novel at least --repeats"),
        (("--model", str(tmp_path / "absent.bundle")), "no such file"),
    ):
        done = run(*args, "--out", str(tmp_path), timeout=60)
        assert done.returncode == 2 and words in done.stderr, (args, done.stderr)
