"""PATCH /v1/classes/{id}: an enrolled class described anew, its samples kept (the
worker's side is in tests/worker/test_worker_redescriptions.py)."""

from __future__ import annotations

from sqlalchemy import select

from app.store.models import Job, ObjectClass
from app.testing.service import names_of, unused_vectors
from tests.service_fixtures import add_sample, problem, register


def test_new_attributes_are_committed_before_the_202_and_the_samples_stay(client, app, dataset):
    created = register(client, dataset, "mug", 0)
    cid = created["class"]["id"]
    add_sample(client, cid, dataset.samples[0])
    vector = unused_vectors(dataset, 2)[1]
    r = client.patch(f"/v1/classes/{cid}", json={"attributes": names_of(vector, dataset)})
    assert r.status_code == 202, r.text
    body = r.json()
    assert body["class"]["id"] == cid and body["class"]["name"] == "mug"
    assert (
        body["class"]["attributes"] == names_of(vector, dataset) and body["class"]["n_samples"] == 1
    )
    job = body["job"]
    assert job["kind"] == "update_class" and job["status"] == "queued" and job["class_id"] == cid
    assert r.headers["location"] == f"/v1/jobs/{job['id']}"
    listed = client.get("/v1/jobs", params={"kind": "update_class"}).json()["jobs"]
    assert [j["id"] for j in listed] == [job["id"]]
    assert client.get(f"/v1/classes/{cid}").json()["attributes"] == names_of(vector, dataset)
    with app.state.service.sessions() as s:  # a fresh session sees both: they are committed
        assert s.get(ObjectClass, cid).attribute_key == ",".join(map(str, vector))
        assert s.get(Job, job["id"]).status == "queued"
    # the old vector is free again, the new one is taken
    old = unused_vectors(dataset, 1)[0]
    assert (
        client.post("/v1/classes", json={"name": "cup", "attribute_vector": old}).status_code == 202
    )
    problem(
        client.post("/v1/classes", json={"name": "bowl", "attribute_vector": vector}),
        409,
        "attribute_vector",
    )


def test_a_description_the_model_could_not_tell_apart_is_refused(client, app, dataset):
    mug = register(client, dataset, "mug", 0)["class"]["id"]
    register(client, dataset, "cup", 1)
    taken = unused_vectors(dataset, 2)[1]
    body = problem(
        client.patch(f"/v1/classes/{mug}", json={"attribute_vector": taken}),
        409,
        "attribute_vector",
    )
    assert "class 'cup' has the same attribute vector" in body["detail"]
    same = unused_vectors(dataset, 1)[0]  # its own description again is no conflict
    assert client.patch(f"/v1/classes/{mug}", json={"attribute_vector": same}).status_code == 202
    with app.state.service.sessions() as s:
        assert s.get(ObjectClass, mug).attribute_key == ",".join(map(str, same))


def test_bad_redescriptions_are_named_and_change_nothing(client, app, dataset):
    mug = register(client, dataset, "mug", 0)["class"]["id"]
    with app.state.service.sessions() as s:
        known = s.scalar(select(ObjectClass).where(ObjectClass.origin == "dataset").limit(1))
        jobs = s.query(Job).count()
    vector = unused_vectors(dataset, 2)[1]
    body = problem(
        client.patch(f"/v1/classes/{known.id}", json={"attribute_vector": vector}),
        409,
        "attribute_vector",
    )
    assert "training dataset" in body["detail"] and "stay fixed" in body["detail"]
    problem(client.patch("/v1/classes/424242", json={"attribute_vector": vector}), 404, "class_id")
    problem(
        client.patch(f"/v1/classes/{mug}", json={"attributes": ["no-such-attribute"]}),
        422,
        "attributes",
    )
    problem(
        client.patch(f"/v1/classes/{mug}", json={"attribute_vector": vector[:-1]}),
        422,
        "attribute_vector",
    )
    problem(client.patch(f"/v1/classes/{mug}", json={}), 422)
    problem(
        client.patch(f"/v1/classes/{mug}", json={"name": "cup", "attribute_vector": vector}),
        422,
        "name",
    )
    assert client.delete(f"/v1/classes/{mug}").status_code == 202
    problem(client.patch(f"/v1/classes/{mug}", json={"attribute_vector": vector}), 404, "class_id")
    with app.state.service.sessions() as s:
        assert s.get(ObjectClass, known.id).attribute_key == known.attribute_key
        assert s.get(ObjectClass, mug).attribute_key == ",".join(
            map(str, unused_vectors(dataset, 1)[0])
        )
        assert s.query(Job).count() == jobs + 1  # the withdrawal's only


def test_a_retried_redescription_is_answered_once(client, app, dataset):
    mug = register(client, dataset, "mug", 0)["class"]["id"]
    vector = unused_vectors(dataset, 2)[1]
    first, again = (
        client.patch(
            f"/v1/classes/{mug}",
            json={"attribute_vector": vector},
            headers={"Idempotency-Key": "fix-mug-1"},
        )
        for _ in range(2)
    )
    assert first.status_code == again.status_code == 202 and first.json() == again.json()
    with app.state.service.sessions() as s:
        assert s.query(Job).filter(Job.kind == "update_class").count() == 1
