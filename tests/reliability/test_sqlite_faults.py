"""SQLite store faults under the real app and worker: a full disk and a data directory that
turns read-only. Writes get a 503 problem with Retry-After, reads keep working, nothing is
half-written, no 202'd enrolment is lost, and once the fault is gone the same requests go
through and ``tactile-zsl store check`` passes.

The full disk is real where this process may mount a small tmpfs (root on Linux): the store
lives on it and a file fills what is left. Elsewhere, and for the read-only directory (root
writes to a read-only file, and a mount with open files cannot be remounted read-only),
the fault is injected where every statement goes through SQLAlchemy: the DBAPI error
SQLite raises for it ('database or disk is full', 'attempt to write a readonly database')
then takes the service's own error paths.
"""

from __future__ import annotations

import contextlib
import uuid

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import text

from app.store.integrity import check_store
from app.testing.faults import MESSAGES, Fault, fill, tiny_filesystem
from app.testing.service import quick_settings, store_check, unused_vectors
from tests.service_fixtures import PROBLEM


def assert_unavailable(r, what: str) -> None:
    assert r.status_code in (503, 507), f"{what}: {r.status_code} {r.text}"
    assert r.headers["content-type"] == PROBLEM, what
    assert r.headers.get("retry-after"), what
    body = r.json()
    assert "SELECT" not in r.text and "INSERT" not in r.text, body  # no SQL leaves


@pytest.mark.parametrize("fault", ["disk full, real", "disk full", "read-only"])
def test_sqlite_store_fault(tmp_path, base_model, fault):
    from app.api.main import create_app
    from worker import Worker

    model, dataset = base_model
    vectors = unused_vectors(dataset, 4)
    sample = dataset.samples[0].tolist()
    with tiny_filesystem(tmp_path / "fs", 64) as mounted:
        if fault == "disk full, real" and not mounted:
            pytest.skip("cannot mount a small tmpfs here (needs root on Linux)")
        data_dir = (tmp_path / "fs" if mounted else tmp_path) / "data"
        settings = quick_settings(data_dir)
        app = create_app(settings, trainer=lambda: base_model)
        state = app.state.service
        engine = state.sessions.kw["bind"]
        with TestClient(app) as client:
            worker = Worker(settings, state.sessions, on_activate=state.holder.serve)
            # a class 202'd before the fault, still queued when it comes
            queued = client.post(
                "/v1/classes", json={"name": "before", "attribute_vector": vectors[0]}
            )
            assert queued.status_code == 202, queued.text
            classes_before = client.get("/v1/classes", params={"limit": 1000}).json()["classes"]

            injected = None
            filler = None
            if fault == "disk full, real":
                with engine.connect() as conn:  # the WAL emptied: the next write needs space
                    conn.execute(text("PRAGMA wal_checkpoint(TRUNCATE)"))
                filler = fill(data_dir.parent)
            else:
                injected = Fault(engine, MESSAGES[fault], after_first=fault == "disk full")
                injected.on = True

            # writes: a 503 (or 507) problem with Retry-After, every kind of them
            key = uuid.uuid4().hex
            body = {"name": "during", "attribute_vector": vectors[1]}
            headers = {"Idempotency-Key": key}
            assert_unavailable(client.post("/v1/classes", json=body, headers=headers), "register")
            cid = queued.json()["class"]["id"]
            assert_unavailable(
                client.post(f"/v1/classes/{cid}/samples", json={"sample": sample}), "add sample"
            )
            assert_unavailable(
                client.patch(f"/v1/classes/{cid}", json={"attribute_vector": vectors[2]}),
                "describe anew",
            )
            # reads: answered, from the served model and the store
            r = client.post("/v1/recognize", json={"samples": [sample]})
            assert r.status_code == 200 and r.json()["model_version"] == 1, r.text
            assert client.get("/v1/classes", params={"limit": 1000}).status_code == 200
            assert client.get("/readyz").status_code == 200  # it answers reads: still ready
            # the worker cannot write either: its round fails, the queued job stays queued
            with contextlib.suppress(Exception):
                worker.run_once()
            assert injected is None or injected.raised >= 4

            # nothing half-written: the store holds what it held
            after = client.get("/v1/classes", params={"limit": 1000}).json()["classes"]
            assert after == classes_before
            job = client.get(f"/v1/jobs/{queued.json()['job']['id']}").json()
            assert job["status"] in ("queued", "running"), job

            # the fault goes: the same request (same key) goes through, not as a replay
            if filler is not None:
                filler.unlink()
            else:
                injected.on = False
                injected.remove()
            retried = client.post("/v1/classes", json=body, headers=headers)
            assert retried.status_code == 202, retried.text
            assert retried.headers.get("idempotent-replayed") is None
            for _ in range(3):  # a round left 'running' by the fault is re-queued by the next
                worker.run_once()
            for job_ref in (queued, retried):
                job = client.get(f"/v1/jobs/{job_ref.json()['job']['id']}").json()
                assert job["status"] == "succeeded", job
            served = client.get("/v1/models/active").json()
            names = {c["name"] for c in served["classes"]}
            assert {"before", "during"} <= names, served
            assert check_store(settings.sqlalchemy_url) == []
        code, out = store_check(settings)
        assert code == 0, out
