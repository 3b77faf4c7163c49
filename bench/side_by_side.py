"""Side by side in one run, on one machine: the service, the framework's floor, a first
scikit-learn service, and the model's own in-process speed.

    .venv/bin/python -m bench.side_by_side [--seconds 10] [--clients 32] [--rounds 5]
                                           [--methods best,paper] [--max-load 1.0]

Three servers on the same stack (uvicorn, uvloop, httptools; no access log), all started
first, then hammered one at a time by the lean keep-alive client of ``bench/load.py``
(``--clients`` connections, one JSON body ``{"samples": [[...32 rows of 30 floats...]]}``,
the simulator's first sample), in ``--rounds`` rounds that each give every phase
``--seconds / --rounds``. Each ratio is taken within a round, between phases run one after
the other, and reported as the median over the rounds (a neighbour's burst on a shared
machine then spoils one round's pair, not the result); absolute figures are medians too:

- the service: ``tactile-zsl serve --processes 1`` on the embedded default (the simulator,
  method ``best``, embedded worker) in a fresh temporary data dir (the first start trains
  the base model), and ``--processes 2`` on the same store; the rate limit is off
  (``TACTILE_RATE_LIMIT=0``, as ``bench/load.py`` runs it), so capacity is measured;
- the same for each other method of ``--methods`` (by default the paper's pipeline,
  ``TACTILE_METHOD=paper``, its default parameters), on a store of its own, measured and
  compared with the floor the same way (phases ``paper_1_process``, ``paper_2_processes``);
- the floor: a bare FastAPI app (``floor_app`` in ``bench/floor_apps.py``) whose
  ``POST /v1/recognize`` parses the body into a float32 array (orjson + numpy) and answers a
  fixed small JSON, on one uvicorn process, and on two that share the port through
  SO_REUSEPORT as the service's processes do;
- a first scikit-learn service (``sklearn_app``, there too): the same parsing, and
  ``ExtraTreesClassifier(n_estimators=100).predict_proba`` of a forest fitted at start-up on
  the simulator's dataset (flattened samples), on one uvicorn process.

Then batch throughput over HTTP (``.npy`` bodies of ``--batch`` samples,
``Content-Type: application/x-npy``, 4 clients as ``bench/load.py``) against the model's own
in-process throughput (``BestRecognizer.recognize_batch`` on the same batch, in this
process, on the model the service trained, read from its store through
``GET /v1/models/active/bundle``, one BLAS thread as the service runs it, measured in each
round between the two HTTP batch phases while the servers idle), and the in-process cost of
``recognize_batch`` on one sample against its batch-amortised cost per sample.

Before anything starts, it waits (polling every 30 s, at most ``--max-wait`` seconds) until
the 1-minute load average is below ``--max-load``: other work on a shared machine spoils
the figures; the load at the start and at the end is in the report. Once every server is
up it waits until they idle (``settle``; ``settled_s`` in the report): a service is ready
before each of its processes has loaded its sentence-embedding model in the background.

It prints JSON: the ratios first, then the targets they are compared with, then the
absolute figures of this machine (each load phase with the cores each server process, the
load generator and everything else on the machine used) and the machine. Every process it
starts is stopped before it exits, also on error or SIGTERM. Only 127.0.0.1 is targeted.
"""

from __future__ import annotations

# The floor and the scikit-learn app, and how they are started, are in bench/floor_apps.py,
# the module uvicorn imports in the servers' own processes. The bench's own machinery
# (bench/load.py, the test harness, the recognizer) is imported inside the functions that
# run in the bench process: the hidden ``--serve`` still starts a server from this module.
import argparse
import contextlib
import io
import os
import platform
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import orjson

from bench.floor_apps import APPS, ROOT, START_TIMEOUT_S, app_server, serve

WARMUP_S = 2.0  # each server and request kind, once, before the first round
ROUND_WARMUP_S = 0.5  # before each measured phase: its connections opened, loop settled
BATCH_CLIENTS = 4  # as bench/load.py's batch phase


# ----------------------------------------------------------------- server processes


@contextlib.contextmanager
def service(data_dir: Path, processes: int, database_url: str = "", method: str = ""):
    """``tactile-zsl serve --processes N`` (embedded worker) on the embedded default, through
    the test harness's ``Cluster``, on a fresh store in ``data_dir`` or on ``database_url``;
    yields (url, pid, its store's URL). ``method``: the method a fresh store is trained with
    (the service's default when empty). Its polling intervals, lease and version count are
    put back to the service's defaults (the harness shortens them)."""
    from app.config import Settings
    from app.framework.registry import DEFAULT_METHOD
    from app.testing.harness import Cluster

    fields = Settings.model_fields
    defaults = {
        f"TACTILE_{name.upper()}": str(fields[name].default)
        for name in ("model_poll_seconds", "worker_poll_seconds", "lease_seconds", "keep_versions")
    }
    env = {
        **defaults,
        "TACTILE_DATASET": "simulated",
        "TACTILE_METHOD": method or DEFAULT_METHOD,
        "TACTILE_METHOD_PARAMS": "{}",
        "TACTILE_RATE_LIMIT": "0",
    }
    cluster = Cluster(
        data_dir,
        database_url,
        n_api=1,
        n_workers=0,
        embedded_worker=True,
        processes=processes,
        extra_env=env,
    )
    try:
        cluster.start()
        cluster.wait_ready(START_TIMEOUT_S)
        yield cluster.urls[0], cluster.apis[0].popen.pid, cluster.sqlalchemy_url
    finally:
        cluster.stop()


# ----------------------------------------------------------------- measurements


#: the servers have settled once each uses less than this share of a core over a second,
#: waited for at most SETTLE_MOST_S seconds
SETTLE_CPU = 0.1
SETTLE_MOST_S = 180.0


def load_phase(url: str, pid: int, seconds: float, clients: int, request: bytes) -> dict:
    """``bench/load.py``'s ``hammer`` after a short warm-up, on a fresh uvloop loop; with
    ``cores_used``: the cores each server process, the load generator and everything else
    on the machine (other users of a shared machine) kept busy meanwhile."""
    import uvloop

    from bench.load import hammer

    async def go() -> dict:
        await hammer([url], ROUND_WARMUP_S, clients, request)
        before = cpu_snapshot(pid)
        out = await hammer([url], seconds, clients, request, pids={"server": pid})
        out["cores_used"] = cores_used(before, cpu_snapshot(pid))
        return out

    return uvloop.run(go())


def settle(pids: list[int], most_s: float = SETTLE_MOST_S) -> float:
    """Seconds until each server of ``pids`` (with its child processes) idles: less than
    ``SETTLE_CPU`` of a core over a second, at most ``most_s``. A service is ready before
    it is done starting: each process then loads the sentence-embedding model in the
    background (``app.api.warm``, many seconds of CPU on a slow machine), which a phase
    measured meanwhile would count as the service's cost per request. (An idle service
    still polls its store for models and jobs: a few per cent of a core.)"""
    from bench.load import process_cpu_s

    def used() -> list[float]:
        return [sum(process_cpu_s(p, children=False) or 0.0 for p in process_tree(q)) for q in pids]

    start = time.monotonic()
    before = used()
    while time.monotonic() - start < most_s:
        time.sleep(1.0)
        now = used()
        if all(b - a < SETTLE_CPU for a, b in zip(before, now, strict=True)):
            break
        before = now
    return round(time.monotonic() - start, 1)


def process_tree(pid: int) -> list[int]:
    from bench.load import child_pids

    try:
        return [pid] + [p for k in child_pids(pid) for p in process_tree(k)]
    except OSError:
        return [pid]


def cpu_snapshot(server: int) -> dict:
    """The machine's busy CPU seconds, and each server process's and this process's own."""
    from bench.load import cpu_jiffies, process_cpu_s

    jiffies = cpu_jiffies()
    busy = sum(jiffies[i] for i in (0, 1, 2, 5, 6)) if jiffies else None  # not idle, io, steal
    return {
        "t": time.monotonic(),
        "busy_s": busy / os.sysconf("SC_CLK_TCK") if busy is not None else None,
        "server": {p: process_cpu_s(p, children=False) for p in process_tree(server)},
        "self": process_cpu_s(os.getpid(), children=False),
    }


def cores_used(before: dict, after: dict) -> dict | None:
    wall = after["t"] - before["t"]
    if before["busy_s"] is None or before["self"] is None or wall <= 0:
        return None
    servers = [
        (after["server"][p] - before["server"][p]) / wall
        for p in after["server"]
        if before["server"].get(p) is not None and after["server"][p] is not None
    ]
    generator = (after["self"] - before["self"]) / wall
    busy = (after["busy_s"] - before["busy_s"]) / wall
    return {
        "server_processes": [round(c, 2) for c in servers if c >= 0.005],
        "load_generator": round(generator, 2),
        "others": round(max(0.0, busy - sum(servers) - generator), 2),
    }


def fetch_bundle(url: str) -> bytes:
    import httpx

    r = httpx.get(f"{url}/v1/models/active/bundle", timeout=60)
    r.raise_for_status()
    return r.content


def load_model(bundle: bytes):
    """The service's model in this process, on one BLAS thread as every serve process runs
    by default (TACTILE_TORCH_THREADS)."""
    from app.framework import bundle as bundles
    from app.framework.runtime import configure_threads

    configure_threads(1)
    return bundles.from_bytes(bundle)


def in_process(model, batch: np.ndarray, seconds: float) -> dict:
    """``recognize_batch`` on the whole batch, then on its first sample, each repeated for
    ``seconds / 2`` (at least 5 calls) after one warm-up call, in this process."""

    def timed(x: np.ndarray) -> list[float]:
        model.recognize_batch(x)
        times, deadline = [], time.monotonic() + seconds / 2
        while len(times) < 5 or time.monotonic() < deadline:
            t = time.perf_counter()
            model.recognize_batch(x)
            times.append(time.perf_counter() - t)
        return times

    before = cpu_snapshot(os.getpid())
    batch_times = timed(batch)
    single_times = timed(batch[:1])
    used = cores_used(before, cpu_snapshot(os.getpid()))
    batch_median = statistics.median(batch_times)
    return {
        "batch_samples_per_s": round(len(batch) * len(batch_times) / sum(batch_times), 1),
        "batch_median_ms": round(1000 * batch_median, 3),
        "batch_amortised_us_per_sample": round(1e6 * batch_median / len(batch), 2),
        "single_median_us": round(1e6 * statistics.median(single_times), 1),
        "single_p99_us": round(1e6 * float(np.percentile(single_times, 99)), 1),
        "batch_calls": len(batch_times),
        "single_calls": len(single_times),
        # this process is both the "server" and the "load generator" here
        "cores_used": used and {"this_process": used["load_generator"], "others": used["others"]},
    }


def machine() -> dict:
    model = "unknown"
    with contextlib.suppress(OSError), open("/proc/cpuinfo") as f:
        model = next(
            (ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")), model
        )
    return {
        "cpu": model,
        "cores": os.cpu_count(),
        "cores_usable": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "python": platform.python_version(),
        "platform": platform.platform(),
    }


def loadavg() -> list[float] | None:
    try:
        with open("/proc/loadavg") as f:
            return [float(v) for v in f.read().split()[:3]]
    except OSError:
        return None


def wait_for_load(max_load: float, max_wait: float, every: float = 30) -> float:
    """Wait until the 1-minute load average is below ``max_load`` (polled every ``every``
    seconds, at most ``max_wait`` seconds in all); the seconds waited."""
    start = time.monotonic()
    while True:
        load = loadavg()
        waited = time.monotonic() - start
        if load is None or load[0] < max_load or waited >= max_wait:
            return round(waited, 1)
        print(f"1-minute load {load[0]:.2f} >= {max_load}: waiting", file=sys.stderr)
        time.sleep(min(every, max(0.0, max_wait - waited)))


def ratio(a: float, b: float, digits: int = 3) -> float | None:
    return round(a / b, digits) if a and b else None


def ratios(r: dict) -> dict:
    """The ratios the targets are stated in, from one round's figures ``r``."""
    s = r["single"]
    floor1, floor2, sk = s["floor_1_process"], s["floor_2_processes"], s["sklearn_1_process"]
    svc1, svc2 = s["service_1_process"], s["service_2_processes"]
    ip = r["in_process"]
    ip_cores = (ip.get("cores_used") or {}).get("this_process")
    ip_per_cpu_s = ip["batch_samples_per_s"] / ip_cores if ip_cores else None

    def per_cpu_s(phase: dict) -> float | None:  # samples per CPU second of the server
        us = (phase.get("cpu_us_per_request") or {}).get("server")
        return phase["samples_per_s"] / phase["rps"] * 1e6 / us if us and phase["rps"] else None

    return {
        "service_over_floor_1_process": {
            "rps": ratio(svc1["rps"], floor1["rps"]),
            "p99": ratio(svc1["p99_ms"], floor1["p99_ms"]),
        },
        "service_over_floor_2_processes": {
            "rps": ratio(svc2["rps"], floor2["rps"]),
            "p99": ratio(svc2["p99_ms"], floor2["p99_ms"]),
        },
        "service_2_processes_over_floor_1_process": {
            "rps": ratio(svc2["rps"], floor1["rps"]),
            "p99": ratio(svc2["p99_ms"], floor1["p99_ms"]),
        },
        **{
            f"{m}_over_floor_{n}": {
                "rps": ratio(s[f"{m}_{n}"]["rps"], s[f"floor_{n}"]["rps"]),
                "p99": ratio(s[f"{m}_{n}"]["p99_ms"], s[f"floor_{n}"]["p99_ms"]),
            }
            for m in other_methods(s)
            for n in ("1_process", "2_processes")
        },
        "sklearn_over_floor_1_process": {
            "rps": ratio(sk["rps"], floor1["rps"], 4),
            "p99": ratio(sk["p99_ms"], floor1["p99_ms"]),
        },
        "http_batch_over_in_process_batch": {
            "1_process": ratio(
                r["batch_http"]["service_1_process"]["samples_per_s"], ip["batch_samples_per_s"]
            ),
            "2_processes": ratio(
                r["batch_http"]["service_2_processes"]["samples_per_s"],
                ip["batch_samples_per_s"],
            ),
        },
        # the service's process overlaps requests on threads and can keep more than one core
        # busy, this process calls recognize_batch on one: the same per CPU second spent
        "http_batch_over_in_process_batch_per_cpu_second": {
            n: ratio(per_cpu_s(r["batch_http"][f"service_{n}"]), ip_per_cpu_s)
            for n in ("1_process", "2_processes")
        },
        "single_in_process_over_batch_amortised_per_sample": ratio(
            ip["single_median_us"], ip["batch_amortised_us_per_sample"], 1
        ),
    }


def other_methods(single: dict) -> list[str]:
    """The methods besides the default measured in a round (``paper`` for phases
    ``paper_1_process`` and ``paper_2_processes``)."""
    return [
        k[: -len("_1_process")]
        for k in single
        if k.endswith("_1_process")
        and k[: -len("_1_process")] not in ("floor", "service", "sklearn")
    ]


def _other_ratio(key: str) -> bool:
    return key.endswith("_over_floor_1_process") and key not in (
        "service_over_floor_1_process",
        "sklearn_over_floor_1_process",
        "service_2_processes_over_floor_1_process",
    )


def targets(q: dict) -> dict:
    """The product owner's targets, each with the measured ratio and whether it is met."""

    def at_least(v, goal):
        return {"goal": f">= {goal}", "measured": v, "met": v is not None and v >= goal}

    def at_most(v, goal):
        return {"goal": f"<= {goal}", "measured": v, "met": v is not None and v <= goal}

    out = {}
    services = ["service"] + [k[: -len("_over_floor_1_process")] for k in q if _other_ratio(k)]
    for name in services:
        for n in ("1_process", "2_processes"):
            s = q[f"{name}_over_floor_{n}"]
            out[f"{name}_rps_over_floor_{n}"] = at_least(s["rps"], 0.8)
            out[f"{name}_p99_over_floor_{n}"] = at_most(s["p99"], 1.25)
    out["http_batch_over_in_process_1_process"] = at_least(
        q["http_batch_over_in_process_batch"]["1_process"], 0.8
    )
    out["single_over_batch_amortised"] = at_most(
        q["single_in_process_over_batch_amortised_per_sample"], 3
    )
    return out


def run(
    seconds: float, clients: int, batch_size: int, rounds: int, methods: tuple[str, ...] = ("best",)
) -> tuple[dict, list[dict]]:
    """Every server started (the service once per method of ``methods``, the first as
    ``service_*``, the others as ``<method>_*``), then ``rounds`` rounds, each measuring every
    server in turn for
    ``seconds / rounds``, and the model in this process, the order reversed every other
    round. Each ratio is taken within a round, between phases measured one after the other
    (a neighbour's burst on a shared machine then spoils a round's pair, not the run), and
    reported as the median over the rounds; the absolute figures as their medians too.
    Returns (absolute figures, each round's figures)."""
    from app.data.simulator import simulate_dataset
    from bench.load import Connection

    samples = simulate_dataset().samples
    single = Connection.prepare(
        "POST",
        "/v1/recognize",
        orjson.dumps({"samples": samples[:1].tolist()}),
        "application/json",
    )
    batch = np.resize(samples, (batch_size, *samples.shape[1:])).astype(np.float32)
    buf = io.BytesIO()
    np.save(buf, batch)
    npy = Connection.prepare("POST", "/v1/recognize", buf.getvalue(), "application/x-npy")
    each = seconds / rounds

    r: dict = {"loadavg_at_start": loadavg(), "start_s": {}}
    with tempfile.TemporaryDirectory(prefix="side-by-side-") as tmp, contextlib.ExitStack() as up:
        tmp = Path(tmp)
        servers: dict[str, tuple[str, int]] = {}
        for kind, workers, name in (
            ("floor", 1, "floor_1_process"),
            ("floor", 2, "floor_2_processes"),
            ("sklearn", 1, "sklearn_1_process"),
        ):
            t = time.monotonic()
            servers[name] = up.enter_context(app_server(kind, workers, tmp))
            r["start_s"][name] = round(time.monotonic() - t, 1)
        r["methods"] = {}
        for i, method in enumerate(methods):
            prefix = "service" if i == 0 else method
            r["methods"][prefix] = method
            store = ""  # the second service serves the store the first one bootstrapped
            for n, name in ((1, f"{prefix}_1_process"), (2, f"{prefix}_2_processes")):
                t = time.monotonic()
                url, pid, store = up.enter_context(service(tmp / name, n, store, method))
                servers[name] = url, pid
                r["start_s"][name] = round(time.monotonic() - t, 1)  # the first trains
        r["settled_s"] = settle([pid for _, pid in servers.values()])
        model = load_model(fetch_bundle(servers["service_1_process"][0]))
        r["in_process_method"] = model.method
        # the pairs of each ratio side by side in the order
        others = [m for m in r["methods"] if m != "service"]
        phases = [
            ("floor_1_process", "single"),
            ("service_1_process", "single"),
            *[(f"{m}_1_process", "single") for m in others],
            ("floor_2_processes", "single"),
            ("service_2_processes", "single"),
            *[(f"{m}_2_processes", "single") for m in others],
            ("sklearn_1_process", "single"),
            ("service_1_process", "batch_http"),
            ("model", "in_process"),
            ("service_2_processes", "batch_http"),
        ]
        requests = {"single": (clients, single), "batch_http": (BATCH_CLIENTS, npy)}
        for name, kind in phases:  # warm-up: first answers, caches, compiled kernels
            if kind == "in_process":
                in_process(model, batch, 0)
            else:
                warm(servers[name][0], WARMUP_S, *requests[kind])
        by_round: list[dict] = []
        for i in range(rounds):
            this: dict = {"single": {}, "batch_http": {}}
            for name, kind in phases if i % 2 == 0 else phases[::-1]:
                if kind == "in_process":
                    this["in_process"] = in_process(model, batch, each)
                    continue
                url, pid = servers[name]
                this[kind][name] = load_phase(url, pid, each, *requests[kind])
                if kind == "batch_http":
                    this[kind][name]["samples_per_s"] = round(this[kind][name]["rps"] * batch_size)
            by_round.append(this)
            print(f"round {i + 1}/{rounds} done", file=sys.stderr)
    for kind in ("single", "batch_http"):
        r[kind] = {name: summarise([x[kind][name] for x in by_round]) for name in by_round[0][kind]}
    r["in_process"] = median_leaves([x["in_process"] for x in by_round])
    r["in_process"]["batch"] = batch_size
    r["loadavg_at_end"] = loadavg()
    return r, by_round


def median_leaves(items: list):
    """The element-wise median of equally shaped nested dicts (None where none has one)."""
    first = items[0]
    if isinstance(first, dict):
        return {k: median_leaves([item[k] for item in items if item is not None]) for k in first}
    if isinstance(first, list):  # e.g. the cores of each server process: kept per round
        return items
    values = [v for v in items if v is not None]
    return round(statistics.median(values), 4) if values else None


def summarise(runs: list[dict]) -> dict:
    """The median over the rounds of a phase's figures, and each round's own."""

    def med(key: str) -> float:
        return round(statistics.median(run[key] for run in runs), 2)

    out = {key: med(key) for key in ("rps", "p50_ms", "p99_ms")}
    if "samples_per_s" in runs[0]:
        out["samples_per_s"] = med("samples_per_s")
    out["requests"] = sum(run["requests"] for run in runs)
    out["errors"] = sum(run["errors"] for run in runs)
    out["rounds"] = [
        {k: run[k] for k in ("rps", "p99_ms", "cpu_us_per_request", "cores_used", "cpu_steal_pct")}
        for run in runs
    ]
    return out


def warm(url: str, seconds: float, clients: int, request: bytes) -> None:
    import uvloop

    from bench.load import hammer

    uvloop.run(hammer([url], seconds, clients, request))


CODE = ("app", "worker", "migrations")


def git(*args: str) -> str:
    done = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True)
    return done.stdout


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument(
        "--seconds",
        type=float,
        default=10,
        help="measured seconds of each phase (one server, one kind of request), split over "
        "the rounds",
    )
    p.add_argument(
        "--rounds", type=int, default=5, help="interleaved rounds over every server (default 5)"
    )
    p.add_argument("--clients", type=int, default=32, help="concurrent single-sample clients")
    p.add_argument("--batch", type=int, default=1024, help="samples per .npy batch")
    p.add_argument(
        "--methods",
        default="best,paper",
        help="the service's methods, comma-separated: the first is measured as 'service' "
        "(the targets' service), each other under its own name (default best,paper)",
    )
    p.add_argument(
        "--max-load",
        type=float,
        default=1.0,
        help="wait until the 1-minute load average is below this before starting (default 1.0)",
    )
    p.add_argument(
        "--max-wait",
        type=float,
        default=600,
        help="the longest wait for --max-load, in seconds; then the run starts anyway "
        "(default 600)",
    )
    p.add_argument("--serve", choices=sorted(APPS), help=argparse.SUPPRESS)
    p.add_argument("--port", type=int, help=argparse.SUPPRESS)
    p.add_argument("--workers", type=int, default=1, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.serve:
        return serve(args.serve, args.port, args.workers)
    if not 0 < args.seconds <= 600 or not 1 <= args.clients <= 1024 or not 1 <= args.rounds <= 20:
        p.error("--seconds must be in (0, 600], --clients in [1, 1024], --rounds in [1, 20]")
    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    from app.framework.registry import METHODS

    unknown = [m for m in methods if m not in METHODS]
    if not methods or unknown or len(set(methods)) != len(methods):
        p.error(f"--methods: distinct names of {sorted(METHODS)} (got {args.methods!r})")
    # SIGTERM unwinds like Ctrl-C, so that every server this run started is stopped
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    waited = wait_for_load(args.max_load, args.max_wait)
    # after the wait: the commit the servers start from (the working tree: code changed
    # since the commit is named with it)
    commit = git("rev-parse", "--short", "HEAD").strip()
    changed = git("status", "--porcelain", "--", *CODE).splitlines()
    absolute, by_round = run(args.seconds, args.clients, args.batch, args.rounds, methods)
    absolute["waited_for_load_s"] = waited
    per_round = [ratios(r) for r in by_round]
    q = median_leaves(per_round)
    report = {
        "ratios": q,
        "targets": targets(q),
        "ratios_by_round": per_round,
        "on_this_machine": absolute,
        "machine": machine(),
        "settings": {
            "seconds": args.seconds,
            "rounds": args.rounds,
            "clients": args.clients,
            "batch": args.batch,
            "methods": list(methods),
            "max_load": args.max_load,
            "batch_clients": BATCH_CLIENTS,
            "warmup_s": WARMUP_S,
            "round_warmup_s": ROUND_WARMUP_S,
            "server_stack": "uvicorn + uvloop + httptools (the service: its coalescing "
            "httptools protocol), no access log, 127.0.0.1",
            "commit": commit,
            "uncommitted_code_changes": [line[3:] for line in changed],
            # the servers import the code at their start, this process at the end
            "code_changed_during_run": git("rev-parse", "--short", "HEAD").strip() != commit
            or git("status", "--porcelain", "--", *CODE).splitlines() != changed,
            "date": time.strftime("%Y-%m-%d"),
        },
    }
    print(orjson.dumps(report, option=orjson.OPT_INDENT_2).decode())
    return 0


if __name__ == "__main__":
    sys.exit(main())
