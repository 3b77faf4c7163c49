"""The ROS 2 bridge's answer latency, publish to answer, beside HTTP's for the same samples,
and a sensor's stream through it: none may be lost.

    .venv/bin/python -m bench.ros2 [--dataset simulated] [--samples 300] [--rate 100]
                                   [--seconds 60] [--pilot-trials 1]
                                   [--out docs/results/ros2]

A real ``tactile-zsl serve`` trains on ``--dataset`` (the service's default method); a
robot's node in this process talks to real ``tactile-zsl ros2`` processes over DDS on
this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, a random domain):

- ``http``: ``--samples`` samples, one request at a time (``POST /v1/recognize``, .npy,
  one kept-alive connection), each request's wall time, measured after the bridges (the
  same samples once before them warm the service);
- ``service`` (``tactile-zsl ros2 --url``) and ``in_process`` (``--model``, the service's
  model file): the same samples published one at a time, each waiting for its answer:
  publish to answer; then a stream of ``--rate`` samples a second for ``--seconds``
  seconds: how many were answered, refused (the queue full) or answered with a problem,
  and each one's latency (answers come in order: the i-th answers the i-th);
- ``pilot`` (``--pilot-trials`` held-out BioTac pilot trials per object, 0 to skip): a
  ``serve`` trained on the others, and their frames replayed at the recorded rate (100 Hz)
  with procedure marks; frames lost, the latency from a procedure's closing mark to its
  answer, and whether each answer equals HTTP's for the same frames.

It writes ``ros2.json`` (percentiles in ms, with the machine and the commit) and
``ros2.png`` (each path's latency distribution), and prints a table. Timings on a machine
shared with other work are noisy: compare the paths of one run.
"""

from __future__ import annotations

import argparse
import io
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from app.testing.ros2 import (
    BridgeProcess,
    RosClient,
    local_ros_environment,
    replay_trial,
    serving,
)
from bench.scale import machine

PILOT = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "biotac_pilot"
PILOT_OBJECTS = ("bouncy_foam", "cork", "glass_bottle", "hard_rough_foam")


def percentiles(seconds: list[float]) -> dict[str, float]:
    ms = np.asarray(seconds) * 1e3
    if not len(ms):
        return {"n": 0}
    return {
        "n": int(len(ms)),
        "p50_ms": round(float(np.percentile(ms, 50)), 3),
        "p99_ms": round(float(np.percentile(ms, 99)), 3),
        "mean_ms": round(float(ms.mean()), 3),
        "max_ms": round(float(ms.max()), 3),
    }


def http_latencies(url: str, samples: np.ndarray) -> list[float]:
    import httpx

    out = []
    with httpx.Client(base_url=url, timeout=30) as http:
        for x in samples:
            body = io.BytesIO()
            np.save(body, x)
            started = time.perf_counter()
            r = http.post(
                "/v1/recognize",
                content=body.getvalue(),
                headers={"Content-Type": "application/x-npy"},
            )
            out.append(time.perf_counter() - started)
            assert r.status_code == 200, r.text
    return out


def one_at_a_time(bridge: BridgeProcess, samples: np.ndarray) -> list[float]:
    out = []
    for x in samples:
        sent = time.perf_counter()
        bridge.publish_samples(x)
        (answer,) = bridge.next_answers(1, timeout=30)
        assert "results" in answer.body, answer.body
        out.append(answer.received - sent)
    return out


def stream(bridge: BridgeProcess, samples: np.ndarray, rate: float, seconds: float) -> dict:
    """``rate`` samples a second for ``seconds``; what came back."""
    n = int(rate * seconds)
    sent = []
    due = time.perf_counter()
    for i in range(n):
        sent.append(time.perf_counter())
        bridge.publish_samples(samples[i % len(samples)])
        due += 1 / rate
        if (wait := due - time.perf_counter()) > 0:
            time.sleep(wait)
    answers = []
    deadline = time.monotonic() + 60
    while len(answers) < n and time.monotonic() < deadline:
        try:
            answers.append(bridge.answers.get(timeout=1))
        except Exception:  # noqa: BLE001 - queue.Empty: keep waiting until the deadline
            continue
    refused = sum(a.body.get("status") == 503 and "queue" in a.body["detail"] for a in answers)
    problems = sum("results" not in a.body for a in answers)
    # each answer names its message (input.sequence, 1 for the first this publisher sent)
    first = answers[0].body["input"]["sequence"] if answers else 1
    paired = [(a, sent[a.body["input"]["sequence"] - first]) for a in answers]
    named = {a.body["input"]["sequence"] for a in answers}
    return {
        "sent": n,
        "answered": len(answers),
        "answered_distinct_inputs": len(named),
        "lost": n - len(answers),
        "refused_queue_full": refused,
        "problems": problems,
        "achieved_rate_hz": round(n / (sent[-1] - sent[0]), 2) if n > 1 else None,
        "latency": percentiles([a.received - s for a, s in paired]),
    }


def bridged(client: RosClient, args: list[str], log: Path, samples, opts) -> dict:
    bridge = BridgeProcess(client, args, log)
    try:
        bridge.wait_ready()
        one_at_a_time(bridge, samples[:10])  # warm: first answers load and connect
        single = one_at_a_time(bridge, samples)
        flowing = stream(bridge, samples, opts.rate, opts.seconds)
        diagnostics = bridge.wait_diagnostics(
            lambda d: d["answered"] == str(10 + len(samples) + flowing["answered"])
        )
        flowing["bridge_refused_queue_full"] = int(diagnostics["refused_queue_full"])
        return {"single": percentiles(single), "stream": flowing, "raw_single_s": single}
    finally:
        assert bridge.stop() == 0, bridge.output()


def pilot(client: RosClient, work: Path, trials_per_object: int) -> dict:
    import httpx

    from app.data.biotac import read_biotac_h5, write_biotac_h5

    folder = work / "biotac"
    folder.mkdir()
    held = []
    for name in PILOT_OBJECTS:
        trials = read_biotac_h5(PILOT / f"{name}.h5")
        names = sorted(trials)
        write_biotac_h5(folder / f"{name}.h5", {n: trials[n] for n in names[trials_per_object:]})
        held += [(name, trials[n]) for n in names[:trials_per_object]]
    (work / "pilot-service").mkdir()
    with serving(work / "pilot-service", {"TACTILE_DATASET": f"biotac:{folder}"}) as url:
        procedures = tuple(httpx.get(f"{url}/v1/models/active").json()["procedures"])
        bridge = BridgeProcess(client, ["--url", url], work / "pilot-bridge.log")
        try:
            bridge.wait_ready()
            latencies, equal, right, published = [], 0, 0, 0
            for name, trial in held:
                replay = replay_trial(bridge, trial, procedures, period=0.01)
                published += replay.frames
                answers = bridge.next_answers(len(procedures), timeout=120)
                latencies += [
                    a.received - t for a, t in zip(answers, replay.completed, strict=True)
                ]
                for a, expected in zip(answers, replay.expected, strict=True):
                    direct = httpx.post(
                        f"{url}/v1/recognize", json={"trials": [expected]}, timeout=120
                    )
                    body = {k: v for k, v in a.body.items() if k != "input"}
                    equal += body == direct.json()
                right += answers[-1].body["results"][0]["class_name"] == name
            diagnostics = bridge.wait_diagnostics(
                lambda d: d["answered"] == str(len(held) * len(procedures))
            )
        finally:
            assert bridge.stop() == 0, bridge.output()
    return {
        "trials": len(held),
        "rate_hz": 100,
        "frames_published": published,
        "frames_received": int(diagnostics["frames"]),
        "frames_lost": published - int(diagnostics["frames"]),
        "answers": len(held) * len(procedures),
        "answers_equal_to_http": equal,
        "recognised_after_last_procedure": right,
        "procedure_to_answer": percentiles(latencies),
    }


def plot(report: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    series = {"HTTP": report["raw"]["http"]}
    for mode in ("service", "in_process"):
        series[f"ROS 2 via {mode.replace('_', '-')}"] = report["raw"][mode]
    fig, ax = plt.subplots(figsize=(7, 4))
    for label, seconds in series.items():
        ms = np.sort(np.asarray(seconds) * 1e3)
        ax.plot(ms, np.arange(1, len(ms) + 1) / len(ms), label=label)
    ax.set_xscale("log")
    ax.set_xlabel("latency of one sample, ms (log)")
    ax.set_ylabel("fraction of samples")
    ax.set_title(f"One sample at a time: ROS 2 publish→answer vs HTTP ({report['dataset']})")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write(report: dict, out: Path) -> None:
    """``ros2.json`` (stamped with the machine and the commit), the raw latencies beside it,
    and ``ros2.png``."""
    stamped = {k: v for k, v in report.items() if k != "raw"}
    stamped["machine"] = machine()
    stamped["note"] = "measured on a machine shared with other work: compare paths of one run"
    (out / "ros2.json").write_text(json.dumps(stamped, indent=2))
    (out / "ros2_raw_latencies.json").write_text(json.dumps(report["raw"]))
    plot(report, out / "ros2.png")


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="bench.ros2", description=__doc__.split("\n\n")[0])
    p.add_argument("--dataset", default="simulated", help="the service's dataset spec")
    p.add_argument("--samples", type=int, default=300, help="samples timed one at a time")
    p.add_argument("--rate", type=float, default=100.0, help="stream rate, samples a second")
    p.add_argument("--seconds", type=float, default=60.0, help="stream length")
    p.add_argument("--pilot-trials", type=int, default=1, help="per object; 0 skips it")
    p.add_argument("--out", default="docs/results/ros2")
    args = p.parse_args(argv)
    if args.samples < 1 or args.rate <= 0 or args.seconds <= 0 or args.pilot_trials < 0:
        p.error("--samples, --rate and --seconds must be positive, --pilot-trials ≥ 0")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    domain = local_ros_environment()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    from app.client import TactileClient
    from app.data.sources import load_dataset

    samples = load_dataset(args.dataset).samples
    pick = np.random.default_rng(0).choice(
        len(samples), args.samples, replace=len(samples) < args.samples
    )
    samples = samples[pick].astype(np.float32)
    client = RosClient()
    report: dict = {"dataset": args.dataset, "ros_domain_id": domain, "raw": {}}
    try:
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            (work / "service").mkdir()
            with serving(work / "service", {"TACTILE_DATASET": args.dataset}) as url:
                model_file = work / "robot.bundle"
                with TactileClient(url, model_file=model_file) as tc:
                    tc.sync_model()
                http_latencies(url, samples)  # warm: the service's first answers load
                for mode, bridge_args in (
                    ("in_process", ["--model", str(model_file)]),
                    ("service", ["--url", url]),
                ):
                    result = bridged(client, bridge_args, work / f"{mode}.log", samples, args)
                    report["raw"][mode] = result.pop("raw_single_s")
                    report[mode] = result
                    print(mode, json.dumps(result))
                report["raw"]["http"] = http_latencies(url, samples)
                report["http"] = percentiles(report["raw"]["http"])
            write(report, out)  # what is measured so far stays if the pilot part fails
            if args.pilot_trials:
                report["pilot"] = pilot(client, work, args.pilot_trials)
                print("pilot", json.dumps(report["pilot"]))
                write(report, out)
    finally:
        client.close()
    print("| path | p50 ms | p99 ms |\n|---|---|---|")
    print(f"| HTTP | {report['http']['p50_ms']} | {report['http']['p99_ms']} |")
    for mode in ("service", "in_process"):
        s = report[mode]["single"]
        print(f"| ROS 2 via {mode} | {s['p50_ms']} | {s['p99_ms']} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
