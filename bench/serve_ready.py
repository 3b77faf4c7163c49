"""How soon ``tactile-zsl serve --dataset SPEC`` becomes ready on a fresh store, on the
service's defaults, and the memory each of its processes holds.

    .venv/bin/python -m bench.serve_ready [--dataset simulated:30000] [--processes N]
                                          [--recognise 100] [--out results/serve-ready/]

The service starts as a subprocess exactly as a user starts it (no ``TACTILE_*`` variable is
passed on; a temporary store and a free port): on an empty store it fits its default method
on the dataset, stores the classes, their samples and the model, then starts its API
processes. Measured:

- ``ready_s``: from the start to ``/readyz`` answering ready with every API process serving;
- ``processes``: each process of the service's session, from ``/proc`` once it is ready:
  ``VmRSS`` (resident), ``VmHWM`` (the kernel's high-water mark of resident memory: for
  ``serve`` itself, which fitted and stored the first model before it began supervising,
  the bootstrap's peak), and ``Pss`` (resident memory with pages shared between processes
  divided among them, from ``smaps_rollup``);
- ``peak_total_gb`` / ``least_available_gb``: the processes' resident memory together at its
  largest, and the machine's least available memory, sampled every half second (below 1 GB
  available the service is stopped and the run fails);
- ``model``: what ``GET /v1/models/active`` says of the first model (its method, the
  probe's choice and seconds where the default chose by probing, its fit's timings);
- ``recognise_1_ms``: ``POST /v1/recognize`` of one sample of the dataset, ``--recognise``
  samples one at a time over one kept-alive connection (median, p90, worst).

The JSON (``serve_ready.json`` in ``--out``) holds every figure, the machine and the commit;
the service's log is kept beside it as ``serve.log``, and ``serve_ready.png`` draws each
process's memory against the goal; a Markdown table goes to stdout and progress to stderr.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from app.data.sources import DatasetSpecError
from bench.scale import machine
from bench.scale_service import MemoryWatch, Service, recognise_latency, say

STARTUP_TIMEOUT_S = 3600
GOALS = {"ready_s": 15 * 60, "api_process_gb": 3.0}  # the service's goals at 30,000 objects


def process_memory(pid: int) -> dict[str, float]:
    """``VmRSS``, ``VmHWM`` (``/proc/PID/status``) and ``Pss`` (``smaps_rollup``) in GB."""
    out = {}
    status = Path(f"/proc/{pid}/status").read_text()
    for key in ("VmRSS", "VmHWM"):
        out[key] = int(re.search(rf"{key}:\s+(\d+) kB", status).group(1)) * 1024 / 1e9
    rollup = Path(f"/proc/{pid}/smaps_rollup").read_text()
    out["Pss"] = int(re.search(r"^Pss:\s+(\d+) kB", rollup, re.M).group(1)) * 1024 / 1e9
    return out


def session_memory(service: Service, pids: dict[int, float]) -> list[dict]:
    """Each process of the service's session: its role and memory, ``serve`` first."""
    rows = []
    for pid in sorted(pids, key=lambda p: (p != service.popen.pid, p)):
        try:
            memory = process_memory(pid)
            cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        except (OSError, AttributeError):
            continue  # gone meanwhile
        if pid == service.popen.pid:
            role = "serve (bootstrap, then supervisor)"
        else:  # API processes are spawned interpreters; others (a refit) are children
            role = "API" if "spawn_main" in cmdline else "child"
        rows.append({"pid": pid, "role": role, **memory})
    return rows


def active_model(url: str) -> dict:
    import httpx

    model = httpx.get(f"{url}/v1/models/active", timeout=30).raise_for_status().json()
    metrics = model.get("metrics") or {}
    return {
        "method": model.get("method"),
        "version": model.get("version"),
        "classes": model.get("class_count"),
        "chosen_by": metrics.get("chosen_by"),
        "timings": metrics.get("timings"),
    }


def table(report: dict) -> str:
    lines = [
        f"`tactile-zsl serve --dataset {report['dataset']}`, {report['api_processes']} API "
        f"processes, model `{report['model']['method']}`",
        "",
        "| figure | measured | goal |",
        "| --- | --- | --- |",
        f"| ready after | {report['ready_s']:.0f} s | {GOALS['ready_s']:.0f} s |",
    ]
    for p in report["processes"]:
        goal = f"{GOALS['api_process_gb']} GB" if p["role"] == "API" else ""
        lines.append(
            f"| {p['role']} {p['pid']}: resident / peak / proportional | {p['VmRSS']:.2f} / "
            f"{p['VmHWM']:.2f} / {p['Pss']:.2f} GB | {goal} |"
        )
    r = report["recognise_1_ms"]
    lines.append(
        f"| recognise one sample (median / p90) | {r['median']:.1f} / {r['p90']:.1f} ms | |"
    )
    lines.append(f"| machine's least available memory | {report['least_available_gb']:.1f} GB | |")
    return "\n".join(lines)


def plot(report: dict, path: Path) -> None:
    """Each process's resident memory and peak, beside the API processes' goal."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = report["processes"]
    labels = [f"{p['role'].split(' ')[0]} {p['pid']}" for p in rows]
    y = range(len(rows))
    fig, ax = plt.subplots(figsize=(7, 0.6 * len(rows) + 1.6))
    ax.barh(y, [p["VmHWM"] for p in rows], color="0.8", label="peak (VmHWM)")
    ax.barh(y, [p["VmRSS"] for p in rows], color="tab:blue", label="resident once ready")
    ax.axvline(GOALS["api_process_gb"], color="tab:red", ls="--", label="goal per API process")
    ax.set_yticks(list(y), labels)
    ax.invert_yaxis()
    ax.set_xlabel("GB")
    ax.set_title(
        f"serve --dataset {report['dataset']} (model {report['model']['method']})\n"
        f"ready in {report['ready_s']:.0f} s (goal {GOALS['ready_s']:.0f} s)",
        fontsize=10,
    )
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dataset", default="simulated:30000", help="the dataset spec served")
    p.add_argument(
        "--processes", type=int, help="API processes (default: the service's, one per core)"
    )
    p.add_argument("--recognise", type=int, default=100, help="samples recognised one by one")
    p.add_argument("--out", type=Path, default=Path("results/serve-ready"))
    args = p.parse_args(argv)
    if args.processes is not None and args.processes < 1:
        p.error("--processes must be at least 1")
    if args.recognise < 1:
        p.error("--recognise must be at least 1")
    try:  # a bad spec fails here, not in serve
        args.samples = drawn_samples(args.dataset, args.recognise)
    except (DatasetSpecError, FileNotFoundError, ValueError) as exc:
        p.error(f"--dataset {args.dataset}: {exc}")
    return args


def drawn_samples(spec: str, n: int) -> np.ndarray:
    """``n`` samples of the dataset ``spec`` names, drawn at random (seed 0), to recognise
    once the service serves; the dataset itself is not held while the service starts."""
    from app.data.sources import open_dataset

    dataset = open_dataset(spec)
    if not hasattr(dataset, "samples"):
        raise ValueError("raw trials are not sent one sample at a time")
    rows = np.random.default_rng(0).choice(len(dataset.samples), size=min(n, len(dataset.samples)))
    return np.asarray(dataset.samples[rows])


def main(argv: list[str] | None = None) -> int:
    from app.client import TactileClient

    args = parse(argv)
    samples = args.samples
    args.out.mkdir(parents=True, exist_ok=True)
    root = Path(tempfile.mkdtemp(prefix="serve-ready-"))
    service = watch = None
    try:
        say(f"starting tactile-zsl serve --dataset {args.dataset} (log: {root / 'serve.log'})")
        t = time.perf_counter()
        service = Service(root, args.dataset, None, args.processes)
        watch = MemoryWatch(service)
        watch.start()  # from the start: the bootstrap's fit is the largest
        service.wait_ready(STARTUP_TIMEOUT_S)
        ready = time.perf_counter() - t
        n_api = service.processes()
        say(f"ready in {ready:.0f} s with {n_api} API processes")
        processes = session_memory(service, watch.processes_gb())
        for p in processes:
            say(f"  {p['role']} {p['pid']}: {p['VmRSS']:.2f} GB resident, {p['Pss']:.2f} GB PSS")
        model = active_model(service.url)
        with TactileClient(service.url, timeout=60) as client:
            recognise = np.asarray(recognise_latency(client, samples)) * 1e3
    finally:
        if watch is not None:
            watch.stop()
        if service is not None:
            service.stop()
            shutil.copyfile(service.log_path, args.out / "serve.log")
        shutil.rmtree(root, ignore_errors=True)
    if watch.stopped_for_memory:
        raise SystemExit("the machine ran out of memory: the service was stopped")
    report = {
        "machine": machine(),
        "dataset": args.dataset,
        "api_processes": n_api,
        "ready_s": ready,
        "processes": processes,
        "peak_total_gb": watch.peak_gb,
        "least_available_gb": watch.least_available_gb,
        "model": model,
        "recognise_1_ms": {
            "median": float(np.median(recognise)),
            "p90": float(np.percentile(recognise, 90)),
            "worst": float(recognise.max()),
        },
        "goals": GOALS,
    }
    api = [p["VmRSS"] for p in processes if p["role"] == "API"]
    report["met"] = {
        "ready_s": ready <= GOALS["ready_s"],
        "api_process_gb": bool(api) and max(api) <= GOALS["api_process_gb"],
    }
    (args.out / "serve_ready.json").write_text(json.dumps(report, indent=2))
    plot(report, args.out / "serve_ready.png")
    print(table(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
