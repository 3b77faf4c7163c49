"""bench/side_by_side.py at tiny size: its floor server (bench/floor_apps.py) starts, answers
the bench's request under load and stops with every process it started; the report's ratios
and targets have the documented shape.

The full run trains the service's base model and takes minutes, so the ratios are checked
here on figures of the same shape as the run's (nothing in a test is timed).
"""

from __future__ import annotations

import os

import orjson

from bench import floor_apps
from bench import side_by_side as sbs
from bench.load import Connection


def test_floor_server_under_load_and_stopped(tmp_path) -> None:
    body = orjson.dumps({"samples": [[[0.5] * 30] * 32]})
    request = Connection.prepare("POST", "/v1/recognize", body, "application/json")
    with floor_apps.app_server("floor", 1, tmp_path) as (url, pid):
        phase = sbs.load_phase(url, pid, 0.3, 2, request)
    assert phase["requests"] > 0 and phase["errors"] == 0
    assert {"rps", "p50_ms", "p99_ms", "cpu_us_per_request", "cores_used"} <= set(phase)
    assert set(phase["cores_used"]) == {"server_processes", "load_generator", "others"}
    try:
        os.kill(pid, 0)
        alive = True
    except ProcessLookupError:
        alive = False
    assert not alive, "the floor server outlived app_server"


def phase(rps: float, p99: float) -> dict:
    return {"rps": rps, "p99_ms": p99}


def single_phases(**more: dict) -> dict:
    """The floor's, the scikit-learn service's and the service's single-sample phases, and
    ``more``."""
    return {
        "floor_1_process": phase(4000, 10),
        "floor_2_processes": phase(5000, 8),
        "sklearn_1_process": phase(100, 400),
        "service_1_process": phase(3600, 11),
        "service_2_processes": phase(3000, 12),
        **more,
    }


def test_ratios_and_targets_shape() -> None:
    absolute = {
        "single": single_phases(),
        "batch_http": {  # 1,024 samples a request
            "service_1_process": {
                "samples_per_s": 30720,
                "rps": 30,
                "cpu_us_per_request": {"server": 40960},
            },
            "service_2_processes": {
                "samples_per_s": 46080,
                "rps": 45,
                "cpu_us_per_request": {"server": 51200},
            },
        },
        "in_process": {
            "cores_used": {"this_process": 1.0, "others": 0.0},
            "batch_samples_per_s": 40960,
            "batch_amortised_us_per_sample": 25,
            "single_median_us": 100,
        },
    }
    q = sbs.ratios(absolute)
    assert list(q)[0] == "service_over_floor_1_process"
    assert q["service_over_floor_1_process"] == {"rps": 0.9, "p99": 1.1}
    assert q["service_over_floor_2_processes"] == {"rps": 0.6, "p99": 1.5}
    assert q["sklearn_over_floor_1_process"]["rps"] == 0.025
    assert q["http_batch_over_in_process_batch"] == {"1_process": 0.75, "2_processes": 1.125}
    per_cpu = q["http_batch_over_in_process_batch_per_cpu_second"]
    assert per_cpu == {"1_process": 0.61, "2_processes": 0.488}
    assert q["single_in_process_over_batch_amortised_per_sample"] == 4.0
    met = {name: t["met"] for name, t in sbs.targets(q).items()}
    assert met == {
        "service_rps_over_floor_1_process": True,
        "service_p99_over_floor_1_process": True,
        "service_rps_over_floor_2_processes": False,
        "service_p99_over_floor_2_processes": False,
        "http_batch_over_in_process_1_process": False,
        "single_over_batch_amortised": False,
    }


def test_median_over_rounds() -> None:
    rounds = [{"a": {"rps": 1.0, "p99": None}, "b": 3}, {"a": {"rps": 3.0, "p99": 2.0}, "b": 1}]
    rounds.append({"a": {"rps": 2.0, "p99": 4.0}, "b": 2})
    assert sbs.median_leaves(rounds) == {"a": {"rps": 2.0, "p99": 3.0}, "b": 2}


def test_other_methods_get_their_ratios_and_targets() -> None:
    absolute = {
        "single": single_phases(paper_1_process=phase(2000, 20), paper_2_processes=phase(4500, 9)),
        "batch_http": {
            name: {"samples_per_s": 30720, "rps": 30, "cpu_us_per_request": {"server": 40960}}
            for name in ("service_1_process", "service_2_processes")
        },
        "in_process": {
            "cores_used": {"this_process": 1.0, "others": 0.0},
            "batch_samples_per_s": 40960,
            "batch_amortised_us_per_sample": 25,
            "single_median_us": 100,
        },
    }
    q = sbs.ratios(absolute)
    assert list(q)[0] == "service_over_floor_1_process"
    assert q["paper_over_floor_1_process"] == {"rps": 0.5, "p99": 2.0}
    assert q["paper_over_floor_2_processes"] == {"rps": 0.9, "p99": 1.125}
    t = sbs.targets(q)
    assert t["paper_rps_over_floor_1_process"]["met"] is False
    assert t["paper_rps_over_floor_2_processes"]["met"] is True
    assert t["paper_p99_over_floor_2_processes"]["met"] is True
    assert t["service_rps_over_floor_1_process"]["met"] is True
    assert not any(k.startswith("sklearn") for k in t)


def test_waits_for_the_load_at_most_max_wait(monkeypatch) -> None:
    loads = iter([[3.0, 1, 1], [2.0, 1, 1], [0.5, 1, 1]])
    monkeypatch.setattr(sbs, "loadavg", lambda: next(loads))
    monkeypatch.setattr(sbs.time, "sleep", lambda s: None)
    assert sbs.wait_for_load(1.0, 600, every=0) >= 0
    assert next(loads, None) is None  # polled until it fell below 1.0
    monkeypatch.setattr(sbs, "loadavg", lambda: [9.0, 9, 9])
    assert sbs.wait_for_load(1.0, 0) == 0  # no waiting allowed: starts at once


def test_settle_waits_while_a_server_is_busy_and_not_after() -> None:
    import subprocess
    import sys

    busy = subprocess.Popen(  # busy for 4 s, then idle
        [
            sys.executable,
            "-c",
            "import time\nend = time.time() + 4\nwhile time.time() < end: pass\ntime.sleep(60)",
        ]
    )
    try:
        assert sbs.settle([busy.pid], most_s=1.5) < 3  # still busy: stopped by most_s
        waited = sbs.settle([busy.pid], most_s=30)
        assert 1.0 <= waited < 10  # waited out the rest of its busy time
        assert sbs.settle([busy.pid], most_s=30) < 2.5  # idle: one quiet second
    finally:
        busy.kill()
        busy.wait()
