"""Coordination through the store only: one retrain of the lineage at a time across
workers, a dead worker's job taken over once its lease expires, bundles content-addressed."""

from __future__ import annotations

import hashlib
import threading
import time
from datetime import timedelta

from sqlalchemy import func, select, update

from app.store import leases, repo
from app.store.db import make_engine, make_sessionmaker
from app.store.models import Bundle, Job, Lease, ModelVersion, utcnow
from app.testing.service import names_of, unused_vectors
from worker import Worker, loop


def register(client, dataset, name: str, i: int) -> int:
    vector = unused_vectors(dataset, i + 1)[i]
    r = client.post("/v1/classes", json={"name": name, "attributes": names_of(vector, dataset)})
    assert r.status_code == 202, r.text
    return r.json()["job"]["id"]


def test_two_workers_never_retrain_at_the_same_time(client, app, settings, dataset, monkeypatch):
    running, peak, lock = [0], [0], threading.Lock()
    original = loop.build

    def tracked_build(*args, **kwargs):
        with lock:
            running[0] += 1
            peak[0] = max(peak[0], running[0])
        try:
            time.sleep(0.3)  # long enough for the other worker to try
            return original(*args, **kwargs)
        finally:
            with lock:
                running[0] -= 1

    monkeypatch.setattr(loop, "build", tracked_build)
    engines = [make_engine(settings.sqlalchemy_url) for _ in range(2)]  # two "processes"
    workers = [Worker(settings, make_sessionmaker(e)) for e in engines]
    stop = threading.Event()
    threads = [threading.Thread(target=w.run, args=(stop,)) for w in workers]
    for t in threads:
        t.start()
    try:
        job_ids = []
        for i in range(4):
            job_ids.append(register(client, dataset, f"c{i}", i))
            time.sleep(0.15)
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            statuses = [client.get(f"/v1/jobs/{j}").json()["status"] for j in job_ids]
            if all(s in ("succeeded", "failed") for s in statuses):
                break
            time.sleep(0.1)
    finally:
        stop.set()
        for t in threads:
            t.join(60)
        for e in engines:
            e.dispose()
    assert statuses == ["succeeded"] * 4
    assert peak[0] == 1
    with app.state.service.sessions() as s:
        versions = repo.list_versions(s)
        # each version builds on the one before it: one lineage, no fork
        assert [v.base_version for v in versions[1:]] == [v.version for v in versions[:-1]]
        assert s.scalar(select(func.count()).where(Job.status == "running")) == 0


def _orphan(app, holder: str, expires_in: float) -> None:
    """A worker elsewhere claimed the queued jobs, holds the lease, then died."""
    with app.state.service.sessions.begin() as s:
        s.add(
            Lease(
                name=loop.LEASE, holder=holder, expires_at=utcnow() + timedelta(seconds=expires_in)
            )
        )
        s.execute(
            update(Job)
            .where(Job.status == "queued")
            .values(status="running", claimed_by=holder, started_at=utcnow())
        )


def test_a_dead_workers_job_is_taken_over_after_its_lease_expires(client, app, worker, dataset):
    job_id = register(client, dataset, "orphan", 0)
    _orphan(app, "other-host:4242:deadbeef", expires_in=1.5)
    assert worker.run_once() == 0  # the lease is alive: hands off
    assert client.get(f"/v1/jobs/{job_id}").json()["status"] == "running"
    time.sleep(1.6)
    assert worker.run_once() == 1  # expired: taken over, job re-queued and done
    job = client.get(f"/v1/jobs/{job_id}").json()
    assert job["status"] == "succeeded" and job["model_version"] == 2


def test_a_dead_local_workers_lease_is_taken_at_once(client, app, worker, dataset):
    job_id = register(client, dataset, "orphan", 0)
    dead_pid = 2**22 + 12345  # above pid_max on Linux: no such process
    _orphan(app, f"{leases.HOST}:{dead_pid}:deadbeef", expires_in=3600)
    assert worker.run_once() == 1
    assert client.get(f"/v1/jobs/{job_id}").json()["status"] == "succeeded"


def test_bundles_are_content_addressed(client, app, worker, dataset):
    register(client, dataset, "mug", 0)
    worker.run_once()
    with app.state.service.sessions() as s:
        for v in s.scalars(select(ModelVersion)):
            data = repo.bundle_data(s, v.bundle_sha256)
            assert hashlib.sha256(data).hexdigest() == v.bundle_sha256
        n = s.scalar(select(func.count()).select_from(Bundle))
        data = repo.bundle_data(s, repo.active_version(s).bundle_sha256)
        assert repo.store_bundle(s, data) == hashlib.sha256(data).hexdigest()
        s.commit()
        assert s.scalar(select(func.count()).select_from(Bundle)) == n  # stored once
