"""The reliability scenarios, sized by their callers: small in tests/reliability, large in
bench/reliability.py. Each drives a workload and returns a report dict; the callers judge it."""

from __future__ import annotations

import itertools
import random
import threading
import time
import uuid
from concurrent.futures import ThreadPoolExecutor

import httpx

from app.framework import bundle
from app.store.integrity import check_store
from app.testing.harness import Cluster, wait_jobs_settled
from app.testing.service import list_all, quick_dataset


def _vectors(n: int) -> list[list[int]]:
    """``n`` attribute vectors no dataset class has (two, then three attributes set)."""
    dataset = quick_dataset()
    taken = {tuple(int(v) for v in row) for row in dataset.class_attributes}
    out = []
    for size in (2, 3):
        for idx in itertools.combinations(range(dataset.n_attributes), size):
            v = [1 if i in idx else 0 for i in range(dataset.n_attributes)]
            if tuple(v) not in taken:
                out.append(v)
            if len(out) == n:
                return out
    raise ValueError(f"fewer than {n} unused attribute vectors")


class Enroller:
    """A robot fleet in one thread: registers classes, adds samples, now and then
    withdraws one, describes a class anew or adds an attribute with values for some
    classes, retrying a timed-out or cut request with the same Idempotency-Key,
    round-robin over the APIs. Vectors are padded with null (not known) for the attributes
    added since the dataset's."""

    def __init__(
        self,
        urls: list[str],
        seed: int = 0,
        max_classes: int = 400,
        headers: dict[str, str] | None = None,
        retry_pause: float = 0.2,
    ) -> None:
        self.urls = itertools.cycle(urls)
        self.headers = headers or {}
        self.retry_pause = retry_pause
        # every attempt: (sent, answered, method, path, status or exception name,
        # content type, Retry-After), monotonic seconds
        self.log: list[tuple[float, float, str, str, int | str, str, str | None]] = []
        self.given_up = 0  # requests no API answered with anything but 503 in 200 attempts
        self.rng = random.Random(seed)
        self.vectors = _vectors(max_classes)
        self.samples = quick_dataset().samples
        self.classes: dict[int, str] = {}  # 202'd class id -> name
        self.sample_ids: list[int] = []  # 202'd sample ids
        self.sample_class: dict[int, int] = {}
        self.withdrawn: list[int] = []  # sample ids whose withdrawal got a 202
        self.described: dict[int, list[int]] = {}  # class id -> vector of its last 202'd PATCH
        self.attributes: list[str] = []  # 202'd attributes, in the order they were added
        # class name -> attribute -> value, as the last 202'd request about either left it
        self.values: dict[str, dict[str, float]] = {}
        self.attribute_lost = False  # an attribute request nobody answered: stop adding
        self.vectors_used = 0
        self.per_class: dict[int, int] = {}
        self.retries = self.replays = self.bad = 0
        self.statuses: dict[int, int] = {}
        self.stop = threading.Event()

    def send(self, method: str, path: str, body: dict | None = None) -> httpx.Response | None:
        key = uuid.uuid4().hex
        for _attempt in range(200):  # a robot keeps retrying until some API answers
            sent = time.monotonic()
            try:
                r = httpx.request(
                    method,
                    next(self.urls) + path,
                    json=body,
                    timeout=10,
                    headers={**self.headers, "Idempotency-Key": key},
                )
            except httpx.TransportError as exc:
                self.log.append(
                    (sent, time.monotonic(), method, path, type(exc).__name__, "", None)
                )
                self.retries += 1
                time.sleep(0.1)
                continue
            self.log.append(
                (
                    sent,
                    time.monotonic(),
                    method,
                    path,
                    r.status_code,
                    r.headers.get("content-type", ""),
                    r.headers.get("retry-after"),
                )
            )
            if r.status_code == 503:  # no model loaded yet, or the store is busy
                self.retries += 1
                time.sleep(self.retry_pause)
                continue
            self.statuses[r.status_code] = self.statuses.get(r.status_code, 0) + 1
            self.replays += r.headers.get("idempotent-replayed") == "true"
            return r
        self.given_up += 1
        return None

    def step(self) -> None:
        if (
            self.classes
            and not self.attribute_lost
            and len(self.attributes) < 5
            and (self.rng.random() < 0.03 or not self.attributes)
        ):
            self._add_attribute()
            return
        kept = sorted(set(self.sample_ids) - set(self.withdrawn))
        # each kind of request at least once, so a short run checks them all
        if kept and (self.rng.random() < 0.1 or not self.withdrawn):  # a sample of the wrong object
            sid = self.rng.choice(kept)
            r = self.send("DELETE", f"/v1/classes/{self.sample_class[sid]}/samples/{sid}")
            if r is not None and r.status_code == 202:
                self.withdrawn.append(sid)
            elif r is not None:
                self.bad += 1
            return
        if (
            self.classes
            and self.vectors_used < len(self.vectors)
            and (self.rng.random() < 0.05 or not self.described)
        ):
            cid = self.rng.choice(sorted(self.classes))  # described wrongly: corrected
            vector = self._next_vector()
            r = self.send("PATCH", f"/v1/classes/{cid}", {"attribute_vector": self._padded(vector)})
            if r is not None and r.status_code == 202:
                self.described[cid] = vector
                self.values.pop(self.classes[cid], None)  # the added ones: not known again
            elif r is not None:
                self.bad += 1
            return
        open_classes = [c for c, n in self.per_class.items() if n < 3]
        if not open_classes or (self.vectors_used < len(self.vectors) and self.rng.random() < 0.5):
            name = f"crash-{len(self.classes)}-{uuid.uuid4().hex[:6]}"
            r = self.send(
                "POST",
                "/v1/classes",
                {"name": name, "attribute_vector": self._padded(self._next_vector())},
            )
            if r is not None and r.status_code == 202:
                cid = r.json()["class"]["id"]
                self.classes[cid] = name
                self.per_class[cid] = 0
            elif r is not None:
                self.bad += 1
            return
        cid = self.rng.choice(open_classes)
        x = self.samples[self.rng.randrange(len(self.samples))]
        r = self.send("POST", f"/v1/classes/{cid}/samples", {"sample": x.tolist()})
        if r is not None and r.status_code == 202:
            self.sample_ids.append(r.json()["sample_id"])
            self.sample_class[self.sample_ids[-1]] = cid
            self.per_class[cid] += 1
        elif r is not None:
            self.bad += 1

    def _add_attribute(self) -> None:
        """A word the vocabulary lacks, with values for a few enrolled classes and one of
        the dataset's."""
        name = f"word-{len(self.attributes)}-{uuid.uuid4().hex[:4]}"
        named = self.rng.sample(sorted(self.classes.values()), min(3, len(self.classes)))
        values = {n: self.rng.choice((0.0, 0.5, 1.0)) for n in named}
        values[quick_dataset().class_names[0]] = 1.0
        r = self.send("POST", "/v1/attributes", {"name": name, "values": values})
        if r is None:
            self.attribute_lost = True
        elif r.status_code == 202:
            self.attributes.append(name)
            for cls, value in values.items():
                self.values.setdefault(cls, {})[name] = value
        else:
            self.bad += 1

    def _padded(self, vector: list[int]) -> list[int | None]:
        return [*vector, *[None] * len(self.attributes)]

    def _next_vector(self) -> list[int]:
        self.vectors_used += 1
        return self.vectors[self.vectors_used - 1]

    def run(self) -> None:
        while not self.stop.is_set():
            self.step()
            time.sleep(0.02)


def verify(
    cluster: Cluster,
    classes: dict[int, str],
    sample_ids: list[int],
    timeout: float,
    withdrawn: list[int] = (),
    described: dict[int, list[int]] | None = None,
    headers: dict[str, str] | None = None,
    attributes: list[str] = (),
    values: dict[str, dict[str, float]] | None = None,
) -> dict:
    """Every 202'd class and sample is in the store and in the active model, except the
    samples whose withdrawal got a 202, which are in neither; a class described anew has
    its last 202'd vector in both; every 202'd attribute is in the vocabulary and the
    served model's, with every 202'd value in the store and the model; jobs settled."""
    counts = wait_jobs_settled(cluster.sqlalchemy_url, timeout)
    url = cluster.urls[0]
    active = httpx.get(f"{url}/v1/models/active", timeout=30, headers=headers).json()
    model_names = {c["name"] for c in active["classes"]}
    with httpx.Client(base_url=url, timeout=30, headers=headers) as client:
        stored = {c["id"]: c for c in list_all(client, "/v1/classes", "classes")}
        vocabulary = client.get("/v1/attributes").json()["attributes"]
        served = bundle.from_bytes(client.get("/v1/models/active/bundle").content).registry
    served_vectors = dict(
        zip(
            served.known_names + served.novel_names,
            [v.tolist() for v in (*served.known_attributes, *served.novel_attributes)],
            strict=True,
        )
    )
    described, values = described or {}, values or {}
    by_name = {c["name"]: c for c in stored.values()}
    position = {a: i for i, a in enumerate(served.attribute_names)}
    from app.store import repo
    from app.store.db import make_engine, make_sessionmaker

    engine = make_engine(cluster.sqlalchemy_url)
    with make_sessionmaker(engine)() as s:
        in_model = set(repo.active_version(s).sample_ids)
        from sqlalchemy import select

        from app.store.models import Job, Sample

        live = select(Sample.id).where(Sample.id.in_(sample_ids), Sample.withdrawn_at.is_(None))
        present = set(s.scalars(live))
        failed = s.execute(
            select(Job.id, Job.kind, Job.sample_id, Job.error).where(Job.status == "failed")
        ).all()
    engine.dispose()
    return {
        "jobs": counts,
        "classes_202": len(classes),
        "classes_missing": sorted(
            c for c in classes if stored.get(c, {}).get("name") != classes[c]
        ),
        "classes_not_in_model": sorted(c for c, n in classes.items() if n not in model_names),
        "samples_202": len(sample_ids),
        "samples_missing": sorted(set(sample_ids) - set(withdrawn) - present),
        "samples_not_in_model": sorted(set(sample_ids) - set(withdrawn) - in_model),
        "withdrawn_202": len(withdrawn),
        "withdrawn_still_live": sorted(set(withdrawn) & present),
        "withdrawn_in_model": sorted(set(withdrawn) & in_model),
        "described_202": len(described),
        "descriptions_not_stored": sorted(
            c
            for c, v in described.items()
            if [a for a in stored.get(c, {}).get("attributes", []) if a not in attributes]
            != [a for a, bit in zip(vocabulary, v, strict=False) if bit]
        ),
        "descriptions_not_served": sorted(
            c
            for c, v in described.items()
            if served_vectors.get(classes[c], [])[: len(v)] != [float(b) for b in v]
        ),
        "attributes_202": len(attributes),
        "attributes_not_stored": [a for a in attributes if a not in vocabulary],
        "attributes_not_served": [a for a in attributes if a not in position],
        "values_202": sum(len(v) for v in values.values()),
        "values_not_stored": sorted(
            (c, a)
            for c, by_attribute in values.items()
            for a, value in by_attribute.items()
            if by_name.get(c, {}).get("attribute_values", {}).get(a) != value
        ),
        "values_not_served": sorted(
            (c, a)
            for c, by_attribute in values.items()
            for a, value in by_attribute.items()
            if a in position and served_vectors.get(c, [None] * len(position))[position[a]] != value
        ),
        "active_version": active["version"],
        # the one failure that is right: a sample withdrawn before a model took it in
        "unexpected_failures": [
            (job_id, kind, error)
            for job_id, kind, sid, error in failed
            if not (kind == "add_sample" and sid in withdrawn and "was withdrawn" in (error or ""))
        ],
        "integrity_problems": check_store(cluster.sqlalchemy_url),
    }


def verify_fleet(
    cluster: Cluster, fleet: Enroller, timeout: float, headers: dict[str, str] | None = None
) -> dict:
    """``verify`` of everything a fleet got a 202 for."""
    return verify(
        cluster,
        fleet.classes,
        fleet.sample_ids,
        timeout,
        fleet.withdrawn,
        fleet.described,
        headers=headers,
        attributes=fleet.attributes,
        values=fleet.values,
    )


def crash(
    cluster: Cluster,
    kills: int,
    seed: int = 0,
    gap: tuple[float, float] = (0.5, 2.5),
    settle_timeout: float = 300,
) -> dict:
    """Fire enrollments and SIGKILL a random API or worker process ``kills`` times,
    restarting it at once; then check nothing that got a 202 was lost."""
    rng = random.Random(seed)
    cluster.start()
    cluster.wait_ready()
    fleet = Enroller(cluster.urls, seed)
    thread = threading.Thread(target=fleet.run, daemon=True)
    thread.start()
    killed: dict[str, int] = {"api": 0, "worker": 0}
    started = time.monotonic()
    try:
        for k in range(kills):  # APIs and workers in turn, a random one of each kind
            time.sleep(rng.uniform(*gap))
            proc = rng.choice(cluster.workers if k % 2 else cluster.apis)
            cluster.kill(proc)
            killed["api" if proc.port else "worker"] += 1
            cluster.start(proc)
    finally:
        fleet.stop.set()
        thread.join(120)
    cluster.wait_ready()
    report = verify_fleet(cluster, fleet, settle_timeout)
    report.update(
        kills=killed,
        seconds=round(time.monotonic() - started, 1),
        retries=fleet.retries,
        replays=fleet.replays,
        statuses=fleet.statuses,
        non_202=fleet.bad,
    )
    return report


def concurrency(cluster: Cluster, clients: int = 100, settle_timeout: float = 300) -> dict:
    """``clients`` robots at once, each registering a class and adding a sample to it."""
    cluster.start()
    cluster.wait_ready()
    vectors = _vectors(clients)
    samples = quick_dataset().samples
    urls = cluster.urls
    statuses: dict[str, int] = {}
    classes: dict[int, str] = {}
    sample_ids: list[int] = []
    lock = threading.Lock()
    barrier = threading.Barrier(clients)

    def robot(i: int) -> None:
        base = urls[i % len(urls)]
        name = f"robot-{i}"
        with httpx.Client(base_url=base, timeout=120) as c:
            barrier.wait()
            try:
                r = c.post(
                    "/v1/classes",
                    json={"name": name, "attribute_vector": vectors[i]},
                    headers={"Idempotency-Key": f"class-{i}"},
                )
                code = str(r.status_code)
                if r.status_code == 202:
                    cid = r.json()["class"]["id"]
                    s = c.post(
                        f"/v1/classes/{cid}/samples",
                        json={"sample": samples[i % len(samples)].tolist()},
                        headers={"Idempotency-Key": f"sample-{i}"},
                    )
                    with lock:
                        classes[cid] = name
                        statuses[str(s.status_code)] = statuses.get(str(s.status_code), 0) + 1
                        if s.status_code == 202:
                            sample_ids.append(s.json()["sample_id"])
            except httpx.TransportError as exc:
                code = type(exc).__name__
            with lock:
                statuses[code] = statuses.get(code, 0) + 1

    started = time.monotonic()
    with ThreadPoolExecutor(clients) as pool:
        list(pool.map(robot, range(clients)))
    report = verify(cluster, classes, sample_ids, settle_timeout)
    report.update(statuses=statuses, seconds=round(time.monotonic() - started, 1))
    return report


def hot_swap(cluster: Cluster, versions: int = 20, load_threads: int = 4) -> dict:
    """Recognition load on every API process while ``versions`` new versions go live."""
    cluster.start()
    cluster.wait_ready()
    urls = cluster.urls
    x = quick_dataset().samples[:1].tolist()
    stop = threading.Event()
    ok, failed, seen = [0], [], set()
    lock = threading.Lock()

    def load(i: int) -> None:
        with httpx.Client(base_url=urls[i % len(urls)], timeout=30) as c:
            while not stop.is_set():
                try:
                    r = c.post("/v1/recognize", json={"samples": x})
                    good = r.status_code == 200
                    with lock:
                        if good:
                            ok[0] += 1
                            seen.add(r.json()["model_version"])
                        else:
                            failed.append(f"{r.status_code} {r.text[:100]}")
                except httpx.HTTPError as exc:
                    with lock:
                        failed.append(repr(exc))

    threads = [threading.Thread(target=load, args=(i,), daemon=True) for i in range(load_threads)]
    for t in threads:
        t.start()
    vectors = _vectors(versions)
    first = httpx.get(f"{urls[0]}/v1/models/active").json()["version"]
    started = time.monotonic()
    with httpx.Client(base_url=urls[0], timeout=30) as c:
        for i in range(versions):  # one enrollment at a time: one new version each
            r = c.post("/v1/classes", json={"name": f"swap-{i}", "attribute_vector": vectors[i]})
            job_id = r.json()["job"]["id"]
            while c.get(f"/v1/jobs/{job_id}", params={"wait": 10}).json()["status"] not in (
                "succeeded",
                "failed",
            ):
                pass
    time.sleep(1.0)  # every process has polled the last one
    stop.set()
    for t in threads:
        t.join(60)
    last = httpx.get(f"{urls[0]}/v1/models/active").json()["version"]
    with httpx.Client(base_url=urls[0], timeout=30) as client:
        stored = list_all(client, "/v1/models", "models")
    return {
        "versions_activated": last - first,
        "recognitions_ok": ok[0],
        "failed": len(failed),
        "failures": failed[:5],
        "versions_served": len(seen),
        "versions_stored": len(stored),
        "integrity_problems": check_store(cluster.sqlalchemy_url),
        "seconds": round(time.monotonic() - started, 1),
    }


def _median(values: list[float]) -> float | None:
    if not values:
        return None
    v = sorted(values)
    mid = len(v) // 2
    return round(v[mid] if len(v) % 2 else (v[mid - 1] + v[mid]) / 2, 2)


def _create_api_key(cluster: Cluster) -> str:
    """An admin key stored in the store with ``tactile-zsl apikey create``: the API
    processes read it from there, so during an outage it works only if they kept it."""
    import subprocess

    from app.testing.harness import tactile_zsl

    out = subprocess.run(
        [*tactile_zsl(), "apikey", "create", "--scope", "admin", "--name", "outage-fleet"],
        env=cluster.env,
        cwd=cluster.data_dir,
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    return out.stdout.strip().splitlines()[-1]


def pg_outage(
    cluster: Cluster,
    server,
    faults: int,
    seed: int = 0,
    gap: tuple[float, float] = (2.0, 5.0),
    down: tuple[float, float] = (1.0, 3.0),
    settle_timeout: float = 300,
) -> dict:
    """The PostgreSQL server under the service (``server``, a
    app.testing.pgserver.PostgresServer) stopped ``faults`` times at random moments
    (fast shutdown, immediate shutdown, SIGKILL of the postmaster, in turn in a random
    order) for a random while and started again, under a load of recognitions,
    descriptions, enrolments and /readyz probes on every API process; no service process
    is restarted. Returns every answer's timing, for the caller's checks."""
    from app.testing.pgserver import STOP_MODES

    rng = random.Random(seed)
    cluster.start()
    cluster.wait_ready()
    key = _create_api_key(cluster)
    headers = {"X-API-Key": key}
    urls = cluster.urls
    deadline = time.monotonic() + 60  # every API has read the key from the store
    while any(httpx.get(f"{u}/v1/attributes", timeout=5).status_code != 401 for u in urls):
        assert time.monotonic() < deadline, "the API processes never required the new key"
        time.sleep(0.2)
    x = quick_dataset().samples[:2].tolist()
    with httpx.Client(headers=headers, timeout=30) as c:
        read_paths = ["/v1/recognize"]
        if c.post(f"{urls[0]}/v1/describe", json={"samples": x}).status_code == 200:
            read_paths.append("/v1/describe")  # the method predicts attributes

    stop = threading.Event()
    lock = threading.Lock()
    reads: list[tuple[float, float, str, int | str, int | None]] = []
    ready: list[tuple[float, float, int, int | str, str]] = []

    def reader(i: int) -> None:  # recognitions and descriptions, alternately
        with httpx.Client(base_url=urls[i % len(urls)], headers=headers, timeout=30) as c:
            for n in itertools.count():
                if stop.is_set():
                    return
                path = read_paths[n % len(read_paths)]
                sent = time.monotonic()
                try:
                    r = c.post(path, json={"samples": x})
                    status, version = r.status_code, r.json().get("model_version")
                except httpx.HTTPError as exc:
                    status, version = type(exc).__name__, None
                with lock:
                    reads.append((sent, time.monotonic(), path, status, version))
                time.sleep(0.02)

    def prober(i: int) -> None:  # /readyz every 0.1 s
        with httpx.Client(base_url=urls[i], timeout=30) as c:
            while not stop.is_set():
                sent = time.monotonic()
                try:
                    r = c.get("/readyz")
                    status, ctype = r.status_code, r.headers.get("content-type", "")
                    if status == 503 and not r.headers.get("retry-after"):
                        ctype += "; no Retry-After"
                except httpx.HTTPError as exc:
                    status, ctype = type(exc).__name__, ""
                with lock:
                    ready.append((sent, time.monotonic(), i, status, ctype))
                time.sleep(0.1)

    fleet = Enroller(urls, seed, headers=headers, retry_pause=0.1)
    threads = [threading.Thread(target=fleet.run, daemon=True)]
    threads += [threading.Thread(target=reader, args=(i,), daemon=True) for i in range(len(urls))]
    threads += [threading.Thread(target=prober, args=(i,), daemon=True) for i in range(len(urls))]
    for t in threads:
        t.start()
    modes: list[str] = []
    used: list[str] = []
    outages: list[tuple[float, float, float]] = []  # (down from, start called, accepting again)
    started = time.monotonic()
    try:
        for _ in range(faults):
            if not modes:
                modes = rng.sample(STOP_MODES, len(STOP_MODES))
            mode = modes.pop()
            time.sleep(rng.uniform(*gap))
            server.stop(mode)
            went_down = time.monotonic()
            time.sleep(rng.uniform(*down))
            restart = time.monotonic()
            server.start()
            outages.append((went_down, restart, time.monotonic()))
            used.append(mode)
        time.sleep(gap[1])  # recovery after the last fault is measured too
    finally:
        fleet.stop.set()
        stop.set()
        for t in threads:
            t.join(120)
    report = verify_fleet(cluster, fleet, settle_timeout, headers)
    report.update(
        _outage_figures(outages, fleet, reads, ready, len(urls)),
        modes=used,
        seconds=round(time.monotonic() - started, 1),
        read_paths=read_paths,
        restarts=[p.name for p in cluster.procs if p.starts != 1 or not p.alive],
        given_up=fleet.given_up,
        statuses=fleet.statuses,
        non_202=fleet.bad,
    )
    return report


def _outage_figures(outages, fleet: Enroller, reads, ready, n_api: int) -> dict:
    """Answers sorted by whether they were sent and answered while the server was down."""

    def inside(sent: float, answered: float) -> bool:
        return any(down <= sent and answered <= restart for down, restart, _ in outages)

    def overlaps(sent: float, answered: float) -> bool:
        return any(sent < up and answered > down for down, _, up in outages)

    writes_in = [e for e in fleet.log if inside(e[0], e[1])]
    reads_in = [e for e in reads if overlaps(e[0], e[1])]
    ready_in = [e for e in ready if inside(e[0], e[1])]
    recovery = []
    for i, (_down, _restart, up) in enumerate(outages):
        until = outages[i + 1][0] if i + 1 < len(outages) else float("inf")
        # every API ready again, and a write accepted, after the server accepts connections
        firsts = [
            min((e[1] for e in ready if e[2] == api and e[0] >= up and e[3] == 200), default=None)
            for api in range(n_api)
        ]
        write = min(
            (e[1] for e in fleet.log if e[0] >= up and e[4] == 202 and e[1] < until), default=None
        )
        points = [*firsts, write]
        recovery.append(
            None if None in points or max(points) > until else round(max(points) - up, 2)
        )
    # an answer is an HTTP status; the rest is an exception's name (cut, timed out)
    statuses = [e[4] for e in writes_in] + [e[3] for e in reads_in + ready_in]
    return {
        "faults": len(outages),
        "requests_during_outage": len(statuses),
        "answered_during_outage": sum(isinstance(st, int) for st in statuses),
        "reads_failed_count": sum(e[3] != 200 for e in reads),
        "outage_seconds": [round(r - d, 2) for d, r, _ in outages],
        "writes_during_outage": len(writes_in),
        "writes_during_outage_statuses": _count(e[4] for e in writes_in),
        "writes_during_outage_bad": [
            e[2:] for e in writes_in if e[4] != 503 or "problem+json" not in e[5] or not e[6]
        ][:10],
        "write_seconds_max": round(max((e[1] - e[0] for e in fleet.log), default=0), 2),
        "write_statuses": _count(e[4] for e in fleet.log),
        "reads_during_outage": len(reads_in),
        "reads_during_outage_failed": [e[2:] for e in reads_in if e[3] != 200][:10],
        "reads": len(reads),
        "reads_failed": [e[2:] for e in reads if e[3] != 200][:10],
        "read_versions": sorted({e[4] for e in reads if e[4] is not None}),
        "readyz_during_outage": len(ready_in),
        "readyz_ready_during_outage": [e[2:] for e in ready_in if e[3] != 503][:10],
        "readyz_not_problem": [
            e[2:] for e in ready_in if "problem+json" not in e[4] or "Retry-After" in e[4]
        ][:10],
        "recovery_seconds": recovery,
        "recovery_median": _median([r for r in recovery if r is not None]),
        "recovery_max": max((r for r in recovery if r is not None), default=None),
    }


def _count(values) -> dict[str, int]:
    out: dict[str, int] = {}
    for v in values:
        out[str(v)] = out.get(str(v), 0) + 1
    return out


def sqlite_faults(data_root, faults: int, requests_per_fault: int = 10, seed: int = 0) -> dict:
    """The real app (in process) and worker on a SQLite store under ``data_root``, through
    ``faults`` store faults in turn: a real full disk (a small tmpfs filled to the last byte,
    where this process may mount one), and injected 'database or disk is full' (after the
    first write of a transaction) and 'attempt to write a readonly database'
    (app/testing/faults.py). During each: ``requests_per_fault`` registrations and as many
    recognitions; then the fault goes and the same registrations are retried with their
    Idempotency-Key. Recovery: from the fault's end to the first 202."""
    import contextlib
    from pathlib import Path

    from fastapi.testclient import TestClient
    from sqlalchemy import text

    from app.api.main import create_app
    from app.testing.faults import MESSAGES, Fault, fill, tiny_filesystem
    from app.testing.service import quick_settings, store_check, trained_base
    from worker import Worker

    base = trained_base()
    vectors = _vectors(faults * requests_per_fault + 1)
    sample = base[1].samples[:1].tolist()
    rng = random.Random(seed)
    root = Path(data_root)
    kinds: list[str] = []
    statuses: dict[str, int] = {}
    reads_failed = answered = sent = 0
    recovery: list[float] = []
    accepted: dict[str, str] = {}  # Idempotency-Key -> class name, once 202'd
    with tiny_filesystem(root / "fs", 64) as mounted:
        settings = quick_settings((root / "fs" if mounted else root) / "data")
        app = create_app(settings, trainer=lambda: base)
        state = app.state.service
        engine = state.sessions.kw["bind"]
        cycle = (["disk full, real"] if mounted else []) + ["disk full", "read-only"]
        with TestClient(app) as client:
            worker = Worker(settings, state.sessions, on_activate=state.holder.serve)
            for i in range(faults):
                kind = cycle[i % len(cycle)]
                kinds.append(kind)
                filler = injected = None
                if kind == "disk full, real":
                    with engine.connect() as conn:
                        conn.execute(text("PRAGMA wal_checkpoint(TRUNCATE)"))
                    filler = fill(root / "fs")
                else:
                    injected = Fault(engine, MESSAGES[kind], after_first=kind == "disk full")
                    injected.on = True
                pending = []
                for j in range(requests_per_fault):
                    name = f"fault-{i}-{j}"
                    body = {"name": name, "attribute_vector": vectors[i * requests_per_fault + j]}
                    key = uuid.uuid4().hex
                    pending.append((key, body))
                    for path, kw in (
                        ("/v1/classes", {"json": body, "headers": {"Idempotency-Key": key}}),
                        ("/v1/recognize", {"json": {"samples": sample}}),
                    ):
                        sent += 1
                        r = client.post(path, **kw)
                        answered += 1
                        statuses[f"{path} {r.status_code}"] = (
                            statuses.get(f"{path} {r.status_code}", 0) + 1
                        )
                        if path == "/v1/recognize" and r.status_code != 200:
                            reads_failed += 1
                        if path == "/v1/classes" and r.status_code == 202:
                            accepted[key] = name
                    time.sleep(rng.uniform(0, 0.05))
                with contextlib.suppress(Exception):  # the worker's round fails too
                    worker.run_once()
                ended = time.monotonic()
                if filler is not None:
                    filler.unlink()
                else:
                    injected.on = False
                    injected.remove()
                first = None
                for key, body in pending:  # the robots retry with the same key
                    for _ in range(100):
                        r = client.post("/v1/classes", json=body, headers={"Idempotency-Key": key})
                        if r.status_code == 202:
                            first = first or time.monotonic()
                            accepted[key] = body["name"]
                            break
                        time.sleep(0.05)
                recovery.append(round(first - ended, 3) if first else None)
                for _ in range(3):
                    worker.run_once()
            served = {c["name"] for c in client.get("/v1/models/active").json()["classes"]}
            problems = check_store(settings.sqlalchemy_url)
        code, out = store_check(settings)
    lost = sorted(n for n in accepted.values() if n not in served)
    done = [r for r in recovery if r is not None]
    return {
        "faults": faults,
        "kinds": kinds,
        "requests_during_faults": sent,
        "answered_during_faults": answered,
        "statuses_during_faults": statuses,
        "reads_failed": reads_failed,
        "registrations_lost": len(lost) + (faults * requests_per_fault - len(accepted)),
        "recovery_seconds": recovery,
        "recovery_median": _median(done),
        "recovery_max": max(done, default=None),
        "integrity_problems": problems,
        "store_check_exit": code,
        "store_check": out.strip().splitlines()[-1:],
    }
