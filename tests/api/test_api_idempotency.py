"""Idempotency-Key on POST /v1/classes and POST /v1/classes/{id}/samples: a robot that
retries after a timeout never enrolls twice."""

from __future__ import annotations

import json
import threading

from sqlalchemy import func, select

from app.store import repo
from app.store.models import IdempotencyRecord, Job, ObjectClass, Sample
from app.testing.service import unused_vectors

PROBLEM = "application/problem+json"


def count(app, model) -> int:
    with app.state.service.sessions() as s:
        return s.scalar(select(func.count()).select_from(model))


def test_same_key_and_body_replays_the_first_answer(client, app, dataset):
    body = {"name": "mug", "attribute_vector": unused_vectors(dataset, 1)[0]}
    headers = {"Idempotency-Key": "robot-7:0001"}
    first = client.post("/v1/classes", json=body, headers=headers)
    assert first.status_code == 202
    classes, jobs = count(app, ObjectClass), count(app, Job)
    again = client.post("/v1/classes", json=body, headers=headers)
    assert again.status_code == 202 and again.json() == first.json()
    assert again.headers["location"] == first.headers["location"]
    assert again.headers["idempotent-replayed"] == "true"
    assert (count(app, ObjectClass), count(app, Job)) == (classes, jobs)
    # the same JSON spaced differently is the same request
    raw = json.dumps(body, indent=4).encode()
    spaced = client.post(
        "/v1/classes", content=raw, headers={**headers, "Content-Type": "application/json"}
    )
    assert spaced.status_code == 202 and spaced.json() == first.json()
    # without the key the same body is a new (here: conflicting) registration
    assert client.post("/v1/classes", json=body).status_code == 409


def test_same_key_with_another_body_is_a_422(client, dataset):
    a, b = unused_vectors(dataset, 2)
    headers = {"Idempotency-Key": "k-1"}
    assert (
        client.post(
            "/v1/classes", json={"name": "a", "attribute_vector": a}, headers=headers
        ).status_code
        == 202
    )
    r = client.post("/v1/classes", json={"name": "b", "attribute_vector": b}, headers=headers)
    assert r.status_code == 422 and r.headers["content-type"] == PROBLEM
    assert [e["field"] for e in r.json()["errors"]] == ["Idempotency-Key"]
    # and on another endpoint too: the path is part of the fingerprint
    r = client.post("/v1/classes/1/samples", json={"sample": [[0.0]]}, headers=headers)
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "Idempotency-Key"


def test_sample_retries_add_one_sample(client, app, dataset, sample):
    created = client.post(
        "/v1/classes", json={"name": "cup", "attribute_vector": unused_vectors(dataset, 1)[0]}
    ).json()
    path = f"/v1/classes/{created['class']['id']}/samples"
    headers = {"Idempotency-Key": "sample-1"}
    before = count(app, Sample)
    answers = [client.post(path, json={"sample": sample}, headers=headers) for _ in range(3)]
    assert {r.status_code for r in answers} == {202}
    assert len({r.json()["sample_id"] for r in answers}) == 1
    assert len({r.json()["job"]["id"] for r in answers}) == 1
    assert count(app, Sample) == before + 1
    # a new key is a new sample
    r = client.post(path, json={"sample": sample}, headers={"Idempotency-Key": "sample-2"})
    assert r.status_code == 202 and count(app, Sample) == before + 2


def test_concurrent_retries_with_one_key_enroll_once(client, app, dataset, sample):
    created = client.post(
        "/v1/classes", json={"name": "jar", "attribute_vector": unused_vectors(dataset, 1)[0]}
    ).json()
    path = f"/v1/classes/{created['class']['id']}/samples"
    before = count(app, Sample)
    answers, gate = [], threading.Barrier(6)

    def retry():
        gate.wait()
        answers.append(
            client.post(path, json={"sample": sample}, headers={"Idempotency-Key": "burst"})
        )

    threads = [threading.Thread(target=retry) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert [r.status_code for r in answers] == [202] * 6, [r.text for r in answers]
    assert len({r.json()["sample_id"] for r in answers}) == 1
    assert count(app, Sample) == before + 1


def test_keys_of_different_api_keys_do_not_collide(client, app, dataset):
    with app.state.service.sessions.begin() as s:
        one, _ = repo.create_api_key(s, "enroll")
        two, _ = repo.create_api_key(s, "enroll")
    app.state.service.keys.refresh()
    a, b = unused_vectors(dataset, 2)
    r1 = client.post(
        "/v1/classes",
        json={"name": "a", "attribute_vector": a},
        headers={"X-API-Key": one, "Idempotency-Key": "same"},
    )
    r2 = client.post(
        "/v1/classes",
        json={"name": "b", "attribute_vector": b},
        headers={"X-API-Key": two, "Idempotency-Key": "same"},
    )
    assert (r1.status_code, r2.status_code) == (202, 202)
    assert r1.json()["class"]["id"] != r2.json()["class"]["id"]
    assert count(app, IdempotencyRecord) == 2


def test_errors_are_not_remembered(client, dataset):
    headers = {"Idempotency-Key": "bad-then-good"}
    r = client.post("/v1/classes", json={"name": "x", "attributes": ["nope"]}, headers=headers)
    assert r.status_code == 422
    # the first try failed and changed nothing; the key is still free
    r = client.post(
        "/v1/classes",
        json={"name": "x", "attribute_vector": unused_vectors(dataset, 1)[0]},
        headers=headers,
    )
    assert r.status_code == 202


def test_malformed_keys_are_a_422(client, dataset):
    body = {"name": "y", "attribute_vector": unused_vectors(dataset, 1)[0]}
    for key in ("k" * 201, "has space"):
        r = client.post("/v1/classes", json=body, headers={"Idempotency-Key": key})
        assert r.status_code == 422 and r.headers["content-type"] == PROBLEM
        assert r.json()["errors"][0]["field"] == "Idempotency-Key"


def test_keys_older_than_the_ttl_are_purged_by_the_worker(client, app, worker, dataset):
    from datetime import UTC, datetime, timedelta

    from sqlalchemy import update

    def register(name: str, vector: list) -> None:
        r = client.post(
            "/v1/classes",
            json={"name": name, "attribute_vector": vector},
            headers={"Idempotency-Key": f"k-{name}"},
        )
        assert r.status_code == 202

    old, fresh = unused_vectors(dataset, 2)
    register("old", old)
    with app.state.service.sessions.begin() as s:  # age the first record past the 24 h default
        s.execute(
            update(IdempotencyRecord).values(created_at=datetime.now(UTC) - timedelta(hours=25))
        )
    register("fresh", fresh)
    worker.run_once()
    with app.state.service.sessions() as s:
        assert set(s.scalars(select(IdempotencyRecord.key))) == {"k-fresh"}
