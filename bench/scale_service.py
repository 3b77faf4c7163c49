"""Scale in objects through the service: how soon enrolments go live over HTTP with
10,000 known objects of the built-in simulator, on the service's defaults.

    .venv/bin/python -m bench.scale_service [--objects 10000] [--novel 200] [--repeats 5]
                                            [--seed 0] [--model FILE] [--recognise 200]
                                            [--processes N] [--in-process-only]
                                            [--out results/scale-service/]

``simulate_dataset(objects + novel, 10 trials, seed)``: the first ``--objects`` objects are
known, the rest novel (as ``bench.scale`` draws them). ``best`` (its defaults, ``n_jobs`` =
the cores) is fitted on every trial of the known objects and saved as
``OUT/best-<objects>-<novel>-<seed>.bundle``, or read from ``--model FILE`` (a bundle this
script wrote for the same ``--objects``, ``--novel`` and ``--seed``: the known classes'
names are checked, their samples cannot be). The known objects are written as a
``folder:`` dataset, and the real service starts on it as a subprocess: ``tactile-zsl serve
--dataset folder:DIR --model FILE`` on a temporary SQLite store and a free port, with the
default number of API processes (``--processes`` sets another, for a machine whose memory
holds fewer), the embedded worker and every other setting at its default (no
``TACTILE_*`` variable is passed on). Then, over HTTP with
``app.client.TactileClient``, for each of ``--repeats`` novel objects whose attribute
vector no known object and no earlier repeat has (the service answers a taken vector with
a 409; ``free_novel`` and ``novel_vectors_taken`` say how many there were):

- ``register_s``: ``POST /v1/classes`` with its attribute vector, from the 202 to its job
  succeeded (``GET /v1/jobs/{id}?wait=``, which answers once the version holding it is
  served by the process that answers);
- ``one_shot_s``: its first real sample (``POST /v1/classes/{id}/samples``), from the 202
  to its job succeeded; the next ``promotion_threshold - 2`` samples follow, each waited for;
- ``promote_s``: the sample that brings it to ``promotion_threshold`` samples, from the 202
  to its job succeeded; the class must then be known, in a version of reason
  ``promotion`` whose ``n_grown_samples`` grew (learnt into the known part, no refit);
- ``*_everywhere_s``: the same until ``EVERYWHERE`` fresh connections in a row (spread
  over the API processes by the kernel) answer ``/healthz`` with that version or newer;
- ``post_ms``: each enrolment POST's own latency (to its 202).

First, in process on the loaded bundle (``in_process``: the method's own share, freed before
the service starts; ``--in-process-only`` stops there): the same objects' registration,
first sample and promotion as calls of the model. Besides: ``memory`` (the resident
memory of each of the service's processes once it is ready, their sum at its largest
during the enrolments, and the machine's least available memory; below 1 GB available
the service is stopped and the run fails), ``startup_s`` (the service's first start:
storing the dataset and the bundle, to ``/readyz``), ``recognise_1_ms`` (``POST
/v1/recognize`` of one known object's sample, an .npy body over one kept-alive
connection, ``--recognise`` different samples). Each figure
is given as its median and worst over the repeats. The JSON (``scale_service.json`` in
``--out``) has every repeat's figures, the machine, the commit and the load averages at
start and end; a Markdown table goes to stdout, progress to stderr.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import zipfile
from pathlib import Path

import numpy as np

from bench.scale import machine

TRIALS = 10
EVERYWHERE = 8  # fresh connections in a row that must see a version
JOB_WAIT_S = 20  # the longest wait GET /v1/jobs/{id} takes
STARTUP_TIMEOUT_S = 1800
FIGURES = ("register", "one_shot", "promote")
FIGURES_IN_PROCESS = ("register_s", "one_shot_s", "promote_s", "promote_encode_s",
                      "promote_new_mb", "load_promoted_s")  # fmt: skip


def say(msg: str) -> None:
    print(f"scale_service: {msg}", file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------ data
def simulate(objects: int, novel: int, seed: int):
    """``simulate_dataset(objects + novel, 10 trials, seed)``: the first ``objects`` known."""
    from app.data.simulator import simulate_dataset

    return simulate_dataset(objects + novel, TRIALS, seed=seed)


def free_novel(ds, objects: int) -> tuple[list[int], int]:
    """The novel objects (indices past ``objects``) whose attribute vector no known object
    and no earlier novel one has, and how many novel vectors a known object has already."""
    vectors = ds.class_attributes
    seen = {tuple(v) for v in vectors[:objects].tolist()}
    taken = sum(tuple(v) in seen for v in vectors[objects:].tolist())
    free = []
    for i in range(objects, ds.n_classes):
        v = tuple(vectors[i].tolist())
        if v not in seen:
            free.append(i)
            seen.add(v)
    return free, taken


def build(known, seed: int, path: Path) -> Path:
    """Fit ``best`` (its defaults, ``n_jobs`` = the cores) on ``known`` and save it."""
    from app.framework import bundle
    from app.framework.registry import make_method

    t = time.perf_counter()
    say(f"fitting best on {known.n_classes} known objects ({len(known)} samples); minutes ...")
    model = make_method("best", seed=seed, n_jobs=os.cpu_count()).fit(known, progress=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    bundle.save(model, path)
    say(f"fitted in {time.perf_counter() - t:.0f} s, saved as {path}")
    return path


def check_model(path: Path, known) -> None:
    """``--model`` must have been fitted on these known objects (their names, at least,
    read from its manifest: the whole bundle is GBs at 10,000 objects)."""
    from app.framework import bundle

    with zipfile.ZipFile(path) as zf:
        manifest = json.loads(zf.read(bundle._MANIFEST))
    names = [c["name"] for c in manifest["classes"] if c["kind"] == "known"]
    if names != list(known.class_names):
        raise SystemExit(
            f"--model {path} was not fitted on the first {known.n_classes} of "
            "simulate_dataset(objects + novel): its known classes differ; fit it with this "
            "script's --objects, --novel and --seed"
        )


# --------------------------------------------------------------------------- service
class Service:
    """``tactile-zsl serve --dataset SPEC`` (with ``--model FILE`` where given, else it fits
    its default method on first start), its store in ``root``, on a free port, with every
    setting at its default."""

    def __init__(
        self, root: Path, dataset: str, model: Path | None, processes: int | None = None
    ) -> None:
        from app.testing.harness import free_port, tactile_zsl

        self.root = root
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        env = {k: v for k, v in os.environ.items() if not k.startswith("TACTILE_")}
        args = ["serve", "--dataset", dataset] + ([] if model is None else ["--model", str(model)])
        args += ["--data-dir", str(root / "store"), "--port", str(self.port)]
        args += [] if processes is None else ["--processes", str(processes)]
        self.log_path = root / "serve.log"
        self._log = self.log_path.open("wb")
        self.popen = subprocess.Popen(
            [*tactile_zsl(), *args],
            env=env,
            cwd=root,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            start_new_session=True,  # its API processes stop with it
        )

    def wait_ready(self, timeout: float) -> None:
        import httpx

        deadline, last = time.monotonic() + timeout, 0.0
        while time.monotonic() < deadline:
            if self.popen.poll() is not None:
                raise RuntimeError(f"serve exited with {self.popen.returncode}:\n{self.tail()}")
            try:
                # ready once every API process serves: the first to answer /readyz may come
                # before the others, which "serving on … with N API processes" waits for
                ready = httpx.get(f"{self.url}/readyz", timeout=2).status_code == 200
                if ready and self.processes() is not None:
                    return
            except httpx.TransportError:
                pass
            if time.monotonic() - last > 30:
                last = time.monotonic()
                lines = self.tail(400).strip().splitlines()
                say(f"  ... starting: {lines[-1] if lines else ''}")
            time.sleep(0.3)
        raise RuntimeError(f"serve not ready after {timeout:.0f} s:\n{self.tail()}")

    def processes(self) -> int | None:
        """How many API processes serve (from its log)."""
        found = re.search(r"with (\d+) API process", self.log_path.read_text(errors="replace"))
        return int(found.group(1)) if found else None

    def tail(self, chars: int = 3000) -> str:
        return self.log_path.read_text(errors="replace")[-chars:]

    def stop(self) -> None:
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGTERM)
            try:
                self.popen.wait(60)
            except subprocess.TimeoutExpired:
                os.killpg(self.popen.pid, signal.SIGKILL)
                self.popen.wait()
        self._log.close()


# ------------------------------------------------------------------------ measuring
class MemoryWatch(threading.Thread):
    """The resident memory of the service's processes (those of its session: ``serve`` and
    its API processes) and the machine's available memory, every ``every`` seconds. When
    the machine's available memory falls below ``floor_gb`` it stops the service (the run
    then fails, ``stopped_for_memory``) before the kernel's OOM killer picks a process."""

    def __init__(self, service: Service, floor_gb: float = 1.0, every: float = 0.5) -> None:
        super().__init__(daemon=True)
        self.service, self.floor_gb, self.every = service, floor_gb, every
        self.peak_gb = 0.0  # the processes' resident memory together, at its largest
        self.least_available_gb = float("inf")
        self.stopped_for_memory = False
        self._done = threading.Event()

    def processes_gb(self) -> dict[int, float]:
        """Each process of the service's session: its resident memory, in GB."""
        out = {}
        for stat in Path("/proc").glob("[0-9]*/stat"):
            try:
                fields = stat.read_text().rsplit(")", 1)[1].split()
                if int(fields[3]) != self.service.popen.pid:  # its session
                    continue
                status = (stat.parent / "status").read_text()
            except (OSError, IndexError, ValueError):
                continue  # gone meanwhile
            found = re.search(r"VmRSS:\s+(\d+) kB", status)
            if found:
                out[int(stat.parent.name)] = int(found.group(1)) * 1024 / 1e9
        return out

    def run(self) -> None:
        while not self._done.wait(self.every):
            self.peak_gb = max(self.peak_gb, sum(self.processes_gb().values()))
            meminfo = Path("/proc/meminfo").read_text()
            available = int(re.search(r"MemAvailable:\s+(\d+) kB", meminfo).group(1)) * 1024
            self.least_available_gb = min(self.least_available_gb, available / 1e9)
            if available / 1e9 < self.floor_gb and not self.stopped_for_memory:
                self.stopped_for_memory = True
                say(f"available memory below {self.floor_gb} GB: stopping the service")
                os.killpg(self.service.popen.pid, signal.SIGKILL)

    def stop(self) -> None:
        self._done.set()

    def figures(self, after_start: dict[int, float]) -> dict:
        return {
            "after_start_gb": sorted(after_start.values(), reverse=True),
            "peak_total_gb": self.peak_gb,
            "least_available_gb": self.least_available_gb,
            "stopped_for_memory": self.stopped_for_memory,
        }


def wait_job(client, job_id: int, timeout: float) -> dict:
    """The job once it has succeeded or failed (RuntimeError after ``timeout`` seconds)."""
    deadline = time.monotonic() + timeout
    while True:
        job = client.job(job_id, wait=JOB_WAIT_S)
        if job["status"] in ("succeeded", "failed"):
            return job
        if time.monotonic() > deadline:
            raise RuntimeError(f"job {job_id} still {job['status']} after {timeout:.0f} s")


def everywhere(url: str, version: int, timeout: float = 60) -> None:
    """Until ``EVERYWHERE`` fresh connections in a row answer ``/healthz`` with ``version``
    or newer: with P API processes, one still serving an older version is missed with
    probability ((P - 1) / P) ** EVERYWHERE (under 4 % for 2)."""
    import httpx

    deadline, row = time.monotonic() + timeout, 0
    while row < EVERYWHERE:
        served = httpx.get(f"{url}/healthz", timeout=5).json().get("model_version") or 0
        row = row + 1 if served >= version else 0
        if time.monotonic() > deadline:
            raise RuntimeError(f"version {version} not served everywhere after {timeout:.0f} s")
        if not row:
            time.sleep(0.01)


def enrol(client, url: str, send, job_timeout: float) -> dict:
    """One enrolment: ``send()`` POSTs it and returns its job; the times to the 202, from
    it to the job succeeded, and to every process serving it."""
    t0 = time.perf_counter()
    job = send()
    t1 = time.perf_counter()
    done = wait_job(client, job["id"], job_timeout)
    t2 = time.perf_counter()
    if done["status"] != "succeeded":
        raise RuntimeError(f"job {done['id']} ({done['kind']}) failed: {done['error']}")
    everywhere(url, done["model_version"])
    t3 = time.perf_counter()
    return {
        "post_ms": (t1 - t0) * 1e3,
        "live_s": t2 - t1,
        "everywhere_s": t3 - t1,
        "job": done,
    }


def one_object(client, url: str, name: str, vector, samples, threshold: int) -> dict:
    """Register one novel object by its vector, add its samples one at a time up to the
    promotion, and check it was promoted by growing the known part."""
    before = client.http.get("/v1/models/active").json()
    grown_before = int(before["metrics"].get("n_grown_samples", 0))
    reg = enrol(
        client,
        url,
        lambda: client.register_class(name, attribute_vector=[float(v) for v in vector])["job"],
        120,
    )
    cid = reg["job"]["class_id"]
    add = lambda i: lambda: client.add_sample(cid, samples[i])["job"]  # noqa: E731
    shot = enrol(client, url, add(0), 120)
    for i in range(1, threshold - 1):
        wait_job(client, add(i)()["id"], 120)
    promote = enrol(client, url, add(threshold - 1), 600)
    cls = client.http.get(f"/v1/classes/{cid}").json()
    version = client.http.get(f"/v1/models/{promote['job']['model_version']}").json()
    grown_after = int(version["metrics"].get("n_grown_samples", 0))
    return {
        "name": name,
        "class_id": cid,
        **{f"register_{k}": v for k, v in reg.items() if k != "job"},
        **{f"one_shot_{k}": v for k, v in shot.items() if k != "job"},
        **{f"promote_{k}": v for k, v in promote.items() if k != "job"},
        "promoted_kind": cls["kind"],
        "promotion_reason": version["reason"],
        "grown_samples_added": grown_after - grown_before,
        "versions": [reg["job"]["model_version"], promote["job"]["model_version"]],
    }


def in_process(model_path: Path, ds, objects: list[int], threshold: int) -> dict:
    """The method's own share of the enrolments, without the service: the bundle loaded,
    then for each novel object ``objects`` (indices into ``ds``), each model having answered
    one sample first as a served model has (``ModelHolder`` answers one before serving it,
    and robots then do; until 87300cc each enrolment copied what that answer leaves on
    the model, the small-batch scorer with its neighbour index), the times of
    ``add_novel_classes`` (``register_s``), ``add_one_shot`` of its first sample
    (``one_shot_s``; the very first also as ``first_one_shot_s``: whatever the load left to
    the first use, which before 006d98e was packing every forest for the walk) and
    ``with_known_samples`` of ``threshold`` samples (``promote_s``: a promotion learnt into
    the known part), each on the model the promotion before made, as the service's worker
    promotes: from the second on, a promotion appends behind its base's rows
    (``app.framework.growing``), while the first copies them (a bundle file's arrays have
    no room behind them; a store's have, ``PartCache.joined``), which the medians, taken
    past the first object, leave out. Each promoted model is then split as the worker
    stores it, after its base (``bundle.PartEncoder``): ``promote_encode_s`` and the bytes
    of the parts its base does not have, ``promote_new_mb`` (``encode_base_s``: the loaded
    bundle's own first split). Each version is stored in a SQLite store of its own, and
    ``load_promoted_s`` is the load of each promoted version by a reader that holds the
    version before, as the API process that did not build it loads it (``PartCache``; the
    reader's first load of the base: ``store_load_base_s``)."""
    from app.framework import bundle

    t = time.perf_counter()
    base = bundle.load(model_path)
    out: dict = {"load_s": time.perf_counter() - t, "repeats": []}
    one = ds.samples[:1]

    def served(model) -> None:  # as an API process serves it: it has answered
        model.recognize(one)

    encoder = bundle.PartEncoder(freeze=True)  # as the worker splits each version it stores
    t = time.perf_counter()
    first_split = encoder.split(base)
    base_parts = first_split[1]
    out["encode_base_s"] = time.perf_counter() - t
    reader = StoreReader(first_split)
    out["store_load_base_s"] = reader.seconds
    promoted = base  # the model the next promotion grows
    for k in objects:
        name, vector = ds.class_names[k], ds.class_attributes[k]
        samples = ds.samples[ds.labels == k]
        served(base)
        t = time.perf_counter()
        novel = base.add_novel_classes([name], vector[None])
        register = time.perf_counter() - t
        served(novel)
        t = time.perf_counter()
        novel.add_one_shot(name, samples[:1])
        shot = time.perf_counter() - t
        out.setdefault("first_one_shot_s", shot)
        served(promoted)
        t = time.perf_counter()
        grown = promoted.with_known_samples({name: samples[:threshold]}, {name: vector})
        promote = time.perf_counter() - t
        out.setdefault("first_promote_s", promote)
        t = time.perf_counter()
        split = encoder.split(grown)  # after its base's split, as the worker stores it
        encode = time.perf_counter() - t
        parts = split[1]
        new_mb = sum(len(b) for sha, b in parts.items() if sha not in base_parts) / 1e6
        promoted, base_parts = grown, parts
        load = reader.load(split)
        out["repeats"].append({"register_s": register, "one_shot_s": shot, "promote_s": promote,
                               "promote_encode_s": encode, "promote_new_mb": new_mb,
                               "load_promoted_s": load})  # fmt: skip
        say(f"  in process {name}: registered {register * 1e3:.1f} ms, one-shot "
            f"{shot * 1e3:.1f} ms, promoted {promote:.2f} s, its version encoded in "
            f"{encode:.2f} s with {new_mb:.1f} MB of new parts, loaded by another reader "
            f"in {load:.2f} s")  # fmt: skip
    reader.close()
    for fig in FIGURES_IN_PROCESS:
        values = [r[fig] for r in out["repeats"][1:] or out["repeats"]]  # past the first
        out[fig] = {"median": float(np.median(values)), "worst": max(values)}
    return out


class StoreReader:
    """A SQLite store of its own, in a temporary directory, holding the versions it is
    given, and a reader of them that holds the one it loaded last as an API process does
    (``ModelHolder``: a ``PartCache`` that keeps only that version's parts); ``seconds``:
    its last load."""

    def __init__(self, split) -> None:
        from app.store import bundles
        from app.store.db import make_engine, make_sessionmaker
        from app.store.migrate import upgrade

        self._dir = Path(tempfile.mkdtemp(prefix="scale-service-store-"))
        self._engine = make_engine(f"sqlite:///{self._dir / 'store.db'}")
        upgrade(self._engine)
        self._sessions = make_sessionmaker(self._engine)
        self._cache = bundles.PartCache()
        self.model = None
        self.load(split)

    def load(self, split) -> float:
        """Store the split version, then load it; the seconds of the load alone."""
        from app.framework import bundle
        from app.store import bundles

        with self._sessions.begin() as s:
            head = bundles.store_model(s, split)
        t = time.perf_counter()
        with self._sessions() as s:
            model = bundles.load_model(s, head, self._cache)
            self._cache.keep_only(set(bundle.part_shas(split[0])))
        self.seconds = time.perf_counter() - t
        self.model = model  # the version before is let go only now, as a swap does
        return self.seconds

    def close(self) -> None:
        self.model = None
        self._engine.dispose()
        shutil.rmtree(self._dir, ignore_errors=True)


def recognise_latency(client, samples: np.ndarray) -> list[float]:
    """Seconds per ``POST /v1/recognize`` of one sample, each sample once."""
    client.recognize(samples[0][None])  # the connection, opened once
    times = []
    for x in samples:
        t = time.perf_counter()
        answer = client.recognize(x[None])
        times.append(time.perf_counter() - t)
        if answer["source"] != "service":
            raise RuntimeError("recognize was answered offline")
    return times


# --------------------------------------------------------------------------- report
def summary(repeats: list[dict], recognise: list[float]) -> dict:
    out = {}
    for fig in FIGURES:
        for part in ("live_s", "everywhere_s", "post_ms"):
            values = [r[f"{fig}_{part}"] for r in repeats]
            out[f"{fig}_{part}"] = {"median": float(np.median(values)), "worst": max(values)}
    ms = np.asarray(recognise) * 1e3
    out["recognise_1_ms"] = {"median": float(np.median(ms)), "worst": float(ms.max())}
    out["recognise_1_ms"]["p90"] = float(np.percentile(ms, 90))
    return out


GOALS_S = {"register": 1.0, "one_shot": 1.0, "promote": 10.0}


def table(report: dict) -> str:
    s, n = report["summary"], report["objects"]
    lines = [
        f"{n} known objects, {len(report['repeats'])} repeats, "
        f"{report['api_processes']} API processes (median / worst):",
        "",
        "| enrolment | 202 → job succeeded | 202 → every process serves it | POST to 202 | goal |",
        "| --- | --- | --- | --- | --- |",
    ]
    for fig in FIGURES:
        live, every, post = (s[f"{fig}_{p}"] for p in ("live_s", "everywhere_s", "post_ms"))
        lines.append(
            f"| {fig.replace('_', '-')} | {live['median']:.3g} / {live['worst']:.3g} s "
            f"| {every['median']:.3g} / {every['worst']:.3g} s "
            f"| {post['median']:.3g} / {post['worst']:.3g} ms | ≤ {GOALS_S[fig]:g} s |"
        )
    r = s["recognise_1_ms"]
    lines.append(
        f"| recognise 1 sample | {r['median']:.3g} / {r['worst']:.3g} ms "
        f"(p90 {r['p90']:.3g} ms) | | | |"
    )
    lines.append(f"\nservice start (dataset and bundle stored): {report['startup_s']:.0f} s")
    m = report["memory"]
    lines.append(
        "resident memory of its processes after the start: "
        + ", ".join(f"{gb:.2f} GB" for gb in m["after_start_gb"])
        + f"; together at most {m['peak_total_gb']:.2f} GB during the enrolments; the "
        f"machine's available memory at least {m['least_available_gb']:.2f} GB"
    )
    return "\n".join(lines)


def in_process_table(figures: dict) -> str:
    """The in-process figures (``in_process``) as Markdown: medians and worst past the first
    object, and the first one-shot apart."""
    lines = ["| in process | median / worst |", "| --- | --- |"]
    for fig, unit, scale in (("register_s", "ms", 1e3), ("one_shot_s", "ms", 1e3),
                             ("promote_s", "s", 1), ("promote_encode_s", "s", 1),
                             ("promote_new_mb", "MB", 1), ("load_promoted_s", "s", 1)):  # fmt: skip
        f = figures[fig]
        label = fig.rsplit("_", 1)[0]
        lines.append(f"| {label} | {f['median'] * scale:.3g} / {f['worst'] * scale:.3g} {unit} |")
    lines.append(f"| first one-shot after the load | {figures['first_one_shot_s']:.3g} s |")
    if "first_promote_s" in figures:  # measured since promotions grow one another
        first = figures["first_promote_s"]
        lines.append(f"| first promotion after the load (copies the file's rows) | {first:.3g} s |")
    lines.append(f"| load the bundle | {figures['load_s']:.3g} s |")
    lines.append(f"| encode the loaded bundle's parts | {figures['encode_base_s']:.3g} s |")
    lines.append(f"| a reader's first load from the store | {figures['store_load_base_s']:.3g} s |")
    return "\n".join(lines)


# ----------------------------------------------------------------------------- main
def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--objects", type=int, default=10_000, help="known objects (default 10000)")
    p.add_argument("--novel", type=int, default=200, help="novel objects drawn (default 200)")
    p.add_argument("--repeats", type=int, default=5, help="novel objects enrolled (default 5)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--model", type=Path, help="a bundle this script fitted before")
    p.add_argument("--recognise", type=int, default=200, help="samples recognised one by one")
    p.add_argument(
        "--processes", type=int, help="API processes (default: the service's, one per core)"
    )
    p.add_argument("--out", type=Path, default=Path("results/scale-service"))
    p.add_argument("--keep", action="store_true", help="keep the service's store and log")
    p.add_argument(
        "--in-process-only",
        action="store_true",
        help="measure the method's share in process and start no service",
    )
    args = p.parse_args(argv)
    if args.objects < 2:
        p.error("--objects must be at least 2")
    if args.repeats < 1 or args.novel < args.repeats:
        p.error("--repeats must be at least 1 and --novel at least --repeats")
    if args.processes is not None and args.processes < 1:
        p.error("--processes must be at least 1")
    if args.recognise < 1:
        p.error("--recognise must be at least 1")
    if args.model is not None and not args.model.is_file():
        p.error(f"--model {args.model}: no such file")
    return args


def main(argv: list[str] | None = None) -> int:
    from app.client import TactileClient
    from app.config import Settings
    from app.data.folder import write_folder

    args = parse(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    load_start = os.getloadavg()
    say(f"simulating {args.objects} + {args.novel} objects ...")
    ds = simulate(args.objects, args.novel, args.seed)
    free, taken = free_novel(ds, args.objects)
    if len(free) < args.repeats:
        raise SystemExit(
            f"only {len(free)} of the {args.novel} novel objects have an attribute vector "
            f"nobody has; --repeats {args.repeats} needs more: raise --novel"
        )
    known = ds.select_classes(np.arange(args.objects))
    if args.model is None:
        name = f"best-{args.objects}-{args.novel}-{args.seed}.bundle"
        model = build(known, args.seed, args.out / name)
    else:
        model = args.model.resolve()
        check_model(model, known)
    threshold = Settings.model_fields["promotion_threshold"].default
    say(f"in process: {args.repeats} novel objects on the loaded bundle ...")
    method = in_process(model, ds, free[: args.repeats], threshold)  # freed before serve starts
    report = {
        "machine": machine(),
        "objects": args.objects,
        "novel": args.novel,
        "free_novel": len(free),
        "novel_vectors_taken": taken,
        "seed": args.seed,
        "model": str(model),
        "promotion_threshold": threshold,
        "in_process": method,
    }
    if args.in_process_only:
        report["load_average"] = {"start": load_start, "end": os.getloadavg()}
        (args.out / "scale_service.json").write_text(json.dumps(report, indent=2))
        print(in_process_table(method))
        return 0
    root = Path(tempfile.mkdtemp(prefix="scale-service-"))
    service = watch = None
    try:
        say(f"writing the known objects as a folder dataset in {root} ...")
        write_folder(known, root / "dataset")
        say(f"starting tactile-zsl serve (log: {root / 'serve.log'}) ...")
        t = time.perf_counter()
        service = Service(root, f"folder:{root / 'dataset'}", model, args.processes)
        service.wait_ready(STARTUP_TIMEOUT_S)
        startup = time.perf_counter() - t
        processes = service.processes()
        say(f"ready in {startup:.0f} s on {service.url} with {processes} API processes")
        watch = MemoryWatch(service)
        after_start = watch.processes_gb()
        say("resident memory: " + ", ".join(f"{gb:.2f} GB" for gb in after_start.values()))
        watch.start()
        repeats = []
        with TactileClient(service.url, timeout=60) as client:
            for r, k in enumerate(free[: args.repeats]):
                samples = ds.samples[ds.labels == k]
                if len(samples) < threshold:
                    raise SystemExit(f"{TRIALS} trials per object, promotion needs {threshold}")
                say(f"repeat {r + 1}/{args.repeats}: {ds.class_names[k]} ...")
                one = one_object(
                    client, service.url, ds.class_names[k], ds.class_attributes[k],
                    samples, threshold,
                )  # fmt: skip
                say(
                    f"  registered {one['register_live_s']:.2f} s, one-shot "
                    f"{one['one_shot_live_s']:.2f} s, promoted {one['promote_live_s']:.2f} s "
                    f"({one['promoted_kind']}, {one['grown_samples_added']} samples grown)"
                )
                repeats.append(one)
            rng = np.random.default_rng(args.seed)
            rows = rng.choice(len(known), size=min(args.recognise, len(known)), replace=False)
            say(f"recognising {len(rows)} samples one at a time ...")
            recognise = recognise_latency(client, known.samples[rows])
    finally:
        if watch is not None:
            watch.stop()
            if watch.stopped_for_memory:
                say(f"stopped for memory: {watch.figures(after_start)}")
        if service is not None:
            service.stop()
            if args.keep:
                say(f"kept {root}")
            else:
                (args.out / "serve.log").write_bytes(service.log_path.read_bytes())
        if not args.keep:
            shutil.rmtree(root, ignore_errors=True)
    report.update(
        load_average={"start": load_start, "end": os.getloadavg()},
        api_processes=processes,
        startup_s=startup,
        memory=watch.figures(after_start),
        summary=summary(repeats, recognise),
        repeats=repeats,
    )
    (args.out / "scale_service.json").write_text(json.dumps(report, indent=2))
    print(table(report))
    print(in_process_table(method))
    return 0


if __name__ == "__main__":
    sys.exit(main())
