"""A stored model whose bytes no longer match their SHA-256 (one byte flipped in the store):
a process that serves a version keeps it, a process that starts falls back to the newest
intact version and says which and why (log and /readyz), and ``tactile-zsl store check``
names the damaged bundle and its version."""

from __future__ import annotations

import logging
import time

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select, update

from app.framework import bundle
from app.framework.errors import BundleError
from app.service import holder as holder_module
from app.store import repo
from app.store.models import Bundle
from app.testing.service import store_check
from tests.service_fixtures import register


def flip_byte(sessions, sha: str) -> bytes:
    """Flip one byte in the middle of stored bundle ``sha``; returns its original bytes."""
    with sessions.begin() as s:
        data = bytes(s.scalar(select(Bundle.data).where(Bundle.sha256 == sha)))
        damaged = bytearray(data)
        damaged[len(data) // 2] ^= 0xFF
        s.execute(update(Bundle).where(Bundle.sha256 == sha).values(data=bytes(damaged)))
    return data


def put_back(sessions, sha: str, data: bytes) -> None:
    with sessions.begin() as s:
        s.execute(update(Bundle).where(Bundle.sha256 == sha).values(data=data))


def version_two(client, worker, dataset) -> str:
    """Enrol a class and let the worker make version 2 (served at once); its head's SHA-256."""
    register(client, dataset, "mug")
    assert worker.run_once() == 1
    assert client.get("/readyz").json()["model_version"] == 2
    with worker.sessions() as s:
        return repo.get_version(s, 2).bundle_sha256


def recognized_by(client, sample) -> int:
    r = client.post("/v1/recognize", json={"samples": [sample]})
    assert r.status_code == 200, r.text
    return r.json()["model_version"]


def test_a_damaged_active_model(settings, app, client, worker, dataset, sample, base_model, caplog):
    head = version_two(client, worker, dataset)
    original = flip_byte(worker.sessions, head)

    # the process serving version 2 keeps serving it
    assert recognized_by(client, sample) == 2
    assert app.state.service.holder.refresh() is False
    assert client.get("/readyz").json() == {"status": "ready", "model_version": 2}

    # store check names the bundle and the version it belongs to
    code, out = store_check(settings)
    assert code == 1, out
    assert f"bundle {head[:12]} does not match its hash (the model of version 2)" in out, out

    # a process starting now falls back to version 1, and says so
    from app.api.main import create_app

    fresh = create_app(settings, trainer=lambda: base_model)
    with caplog.at_level(logging.ERROR, logger="app.service.holder"):
        with TestClient(fresh) as other:
            ready = other.get("/readyz")
            assert ready.status_code == 200, ready.text
            body = ready.json()
            assert body["model_version"] == 1, body
            assert "serving model version 1, not the active version 2" in body["detail"], body
            assert head[:12] in body["detail"], body
            assert recognized_by(other, sample) == 1
    assert any(
        "serving model version 1, not the active version 2" in r.getMessage()
        for r in caplog.records
    ), caplog.text

    put_back(worker.sessions, head, original)
    code, out = store_check(settings)
    assert code == 0, out


def test_a_damaged_new_version_is_not_swapped_in(
    settings, app, client, worker, dataset, sample, monkeypatch
):
    head = version_two(client, worker, dataset)
    assert client.post("/v1/models/1/activate").status_code == 200  # a rollback
    holder = app.state.service.holder
    assert holder.current.version == 1
    original = flip_byte(worker.sessions, head)
    with worker.sessions.begin() as s:  # activated behind the API's back, as a peer could
        assert repo.activate(s, 2)

    # the poller meets the damaged version: version 1 stays served, and /readyz says why
    deadline = time.monotonic() + 10
    while holder.degraded is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert recognized_by(client, sample) == 1
    body = client.get("/readyz").json()
    assert body["model_version"] == 1 and "active version 2" in body["detail"], body
    # an answer that must come from version 2 cannot: a 503 that says why
    r = client.post("/v1/recognize?min_model_version=2", json={"samples": [sample]})
    assert r.status_code == 503, r.text
    problem = r.json()
    assert problem["errors"][0]["field"] == "min_model_version", problem
    assert "not the active version 2" in problem["detail"] and head[:12] in problem["detail"]

    # repaired: tried again (here at once, else every DAMAGED_RETRY_SECONDS) and swapped in
    put_back(worker.sessions, head, original)
    monkeypatch.setattr(holder_module, "DAMAGED_RETRY_SECONDS", 0.0)
    deadline = time.monotonic() + 10
    while holder.current.version != 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert recognized_by(client, sample) == 2
    assert client.get("/readyz").json() == {"status": "ready", "model_version": 2}


def test_a_damaged_part_of_every_version(settings, app, client, worker, dataset, base_model):
    """A part every version shares: store check names it with each version that uses it,
    and a process cannot start (there is nothing intact to serve), saying why."""
    version_two(client, worker, dataset)
    with worker.sessions() as s:
        heads = [repo.get_version(s, v).bundle_sha256 for v in (1, 2)]
        refs = [set(bundle.part_shas(repo.bundle_data(s, h))) for h in heads]
    shared = sorted(refs[0] & refs[1])
    assert shared, "the two versions share no bundle part"
    flip_byte(worker.sessions, shared[0])

    code, out = store_check(settings)
    assert code == 1, out
    assert (
        f"bundle {shared[0][:12]} does not match its hash (a part of version 1; "
        "a part of version 2)" in out
    ), out

    from app.api.main import create_app

    fresh = create_app(settings, trainer=lambda: base_model)
    with pytest.raises(BundleError, match="no earlier version is intact"):
        with TestClient(fresh):
            pass


def test_a_worker_keeps_enrolments_while_the_active_model_is_damaged(client, worker, dataset):
    """A worker that must read the damaged active model neither builds on it nor fails the
    202'd enrolments: they wait, and go through once the bytes are mended."""
    from worker import Worker

    head = version_two(client, worker, dataset)
    original = flip_byte(worker.sessions, head)
    job = register(client, dataset, "cup", 1)["job"]
    other = Worker(worker.settings, worker.sessions)  # holds no model: reads the stored one
    with pytest.raises(BundleError):
        other.run_once()
    assert client.get(f"/v1/jobs/{job['id']}").json()["status"] in ("queued", "running")
    put_back(worker.sessions, head, original)
    assert other.run_once() == 1
    assert client.get(f"/v1/jobs/{job['id']}").json()["status"] == "succeeded"
