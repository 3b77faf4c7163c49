"""API keys with scopes, the rate limit, CORS, and no internals in any response."""

from __future__ import annotations

import hashlib
import time

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select
from sqlalchemy.exc import OperationalError

from app.cli import main as cli
from app.service.keys import RateLimiter
from app.store import repo
from app.store.models import ApiKey
from app.testing.service import unused_vectors
from tests.service_fixtures import PROBLEM, problem


def make_key(app, scope: str, name: str | None = None) -> str:
    with app.state.service.sessions.begin() as s:
        key, _ = repo.create_api_key(s, scope, name)
    app.state.service.keys.refresh()  # the background refresh would see it within a second
    return key


@pytest.fixture
def vectors(dataset):
    return unused_vectors(dataset, 4)


def test_open_until_a_key_exists(client, vectors, sample):
    assert client.get("/v1/classes").status_code == 200
    assert client.post("/v1/recognize", json={"samples": [sample]}).status_code == 200
    r = client.post("/v1/classes", json={"name": "free", "attribute_vector": vectors[0]})
    assert r.status_code == 202


def test_scopes_read_enroll_admin(client, app, vectors, sample):
    read, enroll, admin = (make_key(app, s) for s in ("read", "enroll", "admin"))
    rec = {"samples": [sample]}

    # no key, or an unknown one: 401 on every /v1 route, reads included
    for headers in ({}, {"X-API-Key": "tzk_not-a-key"}):
        problem(client.get("/v1/classes", headers=headers), 401, "X-API-Key")
        problem(client.get("/v1/attributes", headers=headers), 401, "X-API-Key")
        problem(client.get("/v1/models", headers=headers), 401, "X-API-Key")
        problem(client.post("/v1/recognize", json=rec, headers=headers), 401, "X-API-Key")
    assert client.get("/healthz").status_code == 200  # operations stay open
    assert client.get("/readyz").status_code == 200

    # read: GETs and recognize
    h = {"X-API-Key": read}
    assert client.get("/v1/classes", headers=h).status_code == 200
    assert client.get("/v1/models/active", headers=h).status_code == 200
    assert client.post("/v1/recognize", json=rec, headers=h).status_code == 200
    body = {"name": "r", "attribute_vector": vectors[0]}
    problem(client.post("/v1/classes", json=body, headers=h), 403, "X-API-Key")
    problem(client.post("/v1/classes/1/samples", json={"sample": sample}, headers=h), 403)
    problem(client.post("/v1/models/1/activate", headers=h), 403, "X-API-Key")

    # enroll: also register classes and add samples
    h = {"X-API-Key": enroll}
    r = client.post("/v1/classes", json={"name": "e", "attribute_vector": vectors[1]}, headers=h)
    assert r.status_code == 202
    cid = r.json()["class"]["id"]
    assert (
        client.post(f"/v1/classes/{cid}/samples", json={"sample": sample}, headers=h).status_code
        == 202
    )
    assert client.get("/v1/classes", headers=h).status_code == 200
    problem(client.post("/v1/models/1/activate", headers=h), 403, "X-API-Key")

    # admin: also activate (roll back)
    h = {"X-API-Key": admin}
    assert client.post("/v1/models/1/activate", headers=h).status_code == 200
    r = client.post("/v1/classes", json={"name": "a", "attribute_vector": vectors[2]}, headers=h)
    assert r.status_code == 202


def test_every_v1_operation_needs_a_key_once_one_exists(client, app):
    """Walks the OpenAPI schema, so a route added later cannot forget its check, nor
    forget to document it (recognize checks the key inside its one dependency)."""
    read = make_key(app, "read")
    paths = client.get("/openapi.json").json()["paths"]
    operations = [
        (
            method.upper(),
            path.replace("{class_id}", "1")
            .replace("{job_id}", "1")
            .replace("{version}", "1")
            .replace("{sample_id}", "1"),
        )
        for path, item in paths.items()
        if path.startswith("/v1")
        for method in item
    ]
    assert len(operations) == 24  # POST /v1/attributes/interpret, POST /v1/models/choice among them
    for path, item in paths.items():
        for method, operation in item.items():
            if path.startswith("/v1"):
                assert operation.get("security") == [{"APIKeyHeader": []}], (method, path)
    for method, path in operations:
        problem(client.request(method, path), 401, "X-API-Key")
        r = client.request(method, path, headers={"X-API-Key": read})
        writes = method in ("POST", "PATCH", "DELETE") and path not in (
            "/v1/recognize",
            "/v1/describe",
            "/v1/attributes/interpret",  # reads a text, stores nothing
        )
        assert (r.status_code == 403) == writes, (method, path, r.status_code)


def test_revoked_keys_are_refused_and_the_service_stays_locked(client, app):
    key = make_key(app, "admin")
    assert client.get("/v1/classes", headers={"X-API-Key": key}).status_code == 200
    with app.state.service.sessions.begin() as s:
        key_id = s.scalar(select(ApiKey.id))
        assert repo.revoke_api_key(s, key_id)
    app.state.service.keys.refresh()
    problem(client.get("/v1/classes", headers={"X-API-Key": key}), 401, "X-API-Key")
    problem(client.get("/v1/classes"), 401, "X-API-Key")  # not open again


def test_keys_are_stored_hashed_only(client, app):
    key = make_key(app, "enroll", "robot-7")
    with app.state.service.sessions() as s:
        row = s.scalar(select(ApiKey))
        assert row.key_sha256 == hashlib.sha256(key.encode()).hexdigest()
        assert key not in (row.prefix, row.name, row.key_sha256) and len(key) >= 40
        assert row.scope == "enroll" and row.name == "robot-7"


def test_cli_creates_a_key_printed_once_on_the_last_line(
    client, app, settings, monkeypatch, capsys
):
    monkeypatch.setenv("TACTILE_DATABASE_URL", settings.sqlalchemy_url)
    assert cli(["apikey", "create", "--scope", "read", "--name", "cli"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    key = out[-1]
    assert key.startswith("tzk_") and " " not in key
    assert all(key not in line for line in out[:-1])
    app.state.service.keys.refresh()
    assert client.get("/v1/classes", headers={"X-API-Key": key}).status_code == 200
    problem(client.post("/v1/models/1/activate", headers={"X-API-Key": key}), 403)
    assert cli(["apikey", "list"]) == 0
    listing = capsys.readouterr().out
    assert "read" in listing and key not in listing


def test_cli_rejects_an_unknown_scope(capsys):
    with pytest.raises(SystemExit) as exc:
        cli(["apikey", "create", "--scope", "root"])
    assert exc.value.code == 2


# ----------------------------------------------------------------- rate limit


def test_rate_limit_answers_429_with_retry_after_per_key(client, app):
    a, b = make_key(app, "read"), make_key(app, "read")
    app.state.service.limiter = RateLimiter(rate=0.5, burst=3)
    for _ in range(3):
        assert client.get("/v1/attributes", headers={"X-API-Key": a}).status_code == 200
    r = client.get("/v1/attributes", headers={"X-API-Key": a})
    problem(r, 429, "X-API-Key")
    assert int(r.headers["retry-after"]) >= 1
    # another key has its own bucket
    assert client.get("/v1/attributes", headers={"X-API-Key": b}).status_code == 200


def test_token_bucket_refills_at_the_rate():
    # 10 tokens a second: the second request waits up to 0.1 s, less what a busy machine
    # spent between the two calls (a rate of 1,000 a second left no margin for that)
    limiter = RateLimiter(rate=10, burst=1)
    t = time.monotonic()
    assert limiter.acquire("k") == 0
    wait = limiter.acquire("k")
    elapsed = time.monotonic() - t
    assert 0.1 - elapsed - 1e-9 <= wait <= 0.1 and (wait > 0 or elapsed >= 0.1)
    assert RateLimiter(rate=0, burst=1).acquire("k") == 0  # 0 = unlimited


# ----------------------------------------------------------------------- CORS


def test_cors_is_closed_by_default(client):
    preflight = client.options(
        "/v1/classes",
        headers={
            "Origin": "https://evil.example",
            "Access-Control-Request-Method": "POST",
        },
    )
    assert "access-control-allow-origin" not in preflight.headers
    r = client.get("/v1/classes", headers={"Origin": "https://evil.example"})
    assert "access-control-allow-origin" not in r.headers


def test_cors_opens_only_to_configured_origins(settings, base_model):
    from app.api.main import create_app

    app = create_app(
        settings.model_copy(update={"cors_origins": ["https://ops.example"]}),
        trainer=lambda: base_model,
    )
    with TestClient(app) as c:
        ok = c.get("/v1/attributes", headers={"Origin": "https://ops.example"})
        assert ok.headers["access-control-allow-origin"] == "https://ops.example"
        other = c.get("/v1/attributes", headers={"Origin": "https://evil.example"})
        assert "access-control-allow-origin" not in other.headers
        for method in (
            "POST",
            "PATCH",
            "DELETE",
        ):  # an operators' page may enrol, correct, withdraw
            preflight = c.options(
                "/v1/classes/1",
                headers={
                    "Origin": "https://ops.example",
                    "Access-Control-Request-Method": method,
                    "Access-Control-Request-Headers": "X-API-Key, Idempotency-Key",
                },
            )
            assert preflight.status_code == 200, (method, preflight.text)
            assert method in preflight.headers["access-control-allow-methods"]


# ------------------------------------------------------- nothing internal leaks


@pytest.mark.parametrize(
    "error",
    [
        OperationalError("SELECT secret FROM classes WHERE id = 1", {}, Exception("timeout")),
        RuntimeError('Traceback (most recent call last): File "repo.py" SELECT * FROM classes'),
    ],
)
def test_no_stack_trace_or_sql_in_any_response(app, monkeypatch, error):
    def broken(*_args):
        raise error

    with TestClient(app, raise_server_exceptions=False) as c:
        monkeypatch.setattr(repo, "list_classes", broken)
        r = c.get("/v1/classes")
    assert r.status_code in (500, 503) and r.headers["content-type"] == PROBLEM
    text = r.text.lower()
    for leak in ("select", "traceback", "repo.py", "secret", "classes where"):
        assert leak not in text, r.text
    if isinstance(error, OperationalError):
        assert r.status_code == 503 and r.headers["retry-after"]


def test_every_job_records_who_queued_it(client, app, vectors, sample):
    r = client.post("/v1/classes", json={"name": "open", "attribute_vector": vectors[0]})
    assert r.json()["job"]["requested_by"] == "addr:testclient"  # no keys yet: the address
    robot = make_key(app, "enroll", "robot-7")
    with app.state.service.sessions() as s:
        key_id = s.scalar(select(ApiKey.id).where(ApiKey.name == "robot-7"))
    h = {"X-API-Key": robot}
    r = client.post(
        "/v1/classes", json={"name": "by-key", "attribute_vector": vectors[1]}, headers=h
    )
    cid = r.json()["class"]["id"]
    jobs = [r.json()["job"]]
    r = client.post(f"/v1/classes/{cid}/samples", json={"sample": sample}, headers=h)
    jobs.append(r.json()["job"])
    jobs.append(
        client.delete(f"/v1/classes/{cid}/samples/{r.json()['sample_id']}", headers=h).json()["job"]
    )
    jobs.append(client.delete(f"/v1/classes/{cid}", headers=h).json()["job"])
    assert [j["kind"] for j in jobs] == [
        "register_class",
        "add_sample",
        "withdraw_sample",
        "withdraw_class",
    ]
    for j in jobs:
        stored = client.get(f"/v1/jobs/{j['id']}", headers=h).json()
        assert j["requested_by"] == stored["requested_by"] == f"key:{key_id}"
