"""DELETE /v1/classes/{id} and DELETE /v1/classes/{id}/samples/{id}: what the API does at
once (the worker's side is in tests/worker/test_worker_withdrawals.py)."""

from __future__ import annotations

from sqlalchemy import select

from app.store.models import Job, ObjectClass, Sample
from app.testing.service import names_of, unused_vectors
from tests.service_fixtures import add_sample, problem, register


def enrol(client, dataset, name: str = "mug", i: int = 0) -> tuple[int, int]:
    """A registered class with one sample: (class id, sample id)."""
    cid = register(client, dataset, name, i)["class"]["id"]
    return cid, add_sample(client, cid, dataset.samples[0])["sample_id"]


def test_withdrawing_a_sample_is_committed_before_the_202(client, app, dataset):
    cid, sid = enrol(client, dataset)
    r = client.delete(f"/v1/classes/{cid}/samples/{sid}")
    assert r.status_code == 202, r.text
    body = r.json()
    assert body["class_id"] == cid and body["sample_id"] == sid
    job = body["job"]
    assert job["kind"] == "withdraw_sample" and job["status"] == "queued"
    assert job["class_id"] == cid and job["sample_id"] == sid
    assert r.headers["location"] == f"/v1/jobs/{job['id']}"
    assert client.get(f"/v1/classes/{cid}").json()["n_samples"] == 0
    with (
        app.state.service.sessions() as s
    ):  # kept, marked: jobs and model versions still refer to it
        row = s.get(Sample, sid)
        assert row is not None and row.withdrawn_at is not None
        assert s.get(Job, job["id"]).status == "queued"
    problem(client.delete(f"/v1/classes/{cid}/samples/{sid}"), 404, "sample_id")  # not twice


def test_withdrawing_a_class_takes_its_samples_and_frees_its_name(client, app, dataset):
    cid, sid = enrol(client, dataset)
    r = client.delete(f"/v1/classes/{cid}")
    assert r.status_code == 202, r.text
    body = r.json()
    assert body["class_id"] == cid and body["sample_id"] is None
    assert body["job"]["kind"] == "withdraw_class"
    problem(client.get(f"/v1/classes/{cid}"), 404, "class_id")
    assert cid not in [
        c["id"] for c in client.get("/v1/classes", params={"limit": 1000}).json()["classes"]
    ]
    problem(client.delete(f"/v1/classes/{cid}"), 404, "class_id")
    problem(
        client.post(f"/v1/classes/{cid}/samples", json={"sample": dataset.samples[0].tolist()}),
        404,
        "class_id",
    )
    with app.state.service.sessions() as s:
        assert s.get(ObjectClass, cid).withdrawn_at is not None
        assert s.get(Sample, sid).withdrawn_at is not None

    # the same name again, with other attributes: the same class, new vector, no samples
    vector = unused_vectors(dataset, 2)[1]
    r = client.post("/v1/classes", json={"name": "mug", "attributes": names_of(vector, dataset)})
    assert r.status_code == 202, r.text
    again = r.json()["class"]
    assert again["id"] == cid and again["attributes"] == names_of(vector, dataset)
    assert again["n_samples"] == 0 and again["kind"] == "novel"


def test_a_withdrawn_class_no_longer_holds_its_attribute_vector(client, dataset):
    cid, _ = enrol(client, dataset)
    vector = unused_vectors(dataset, 1)[0]
    problem(
        client.post("/v1/classes", json={"name": "cup", "attribute_vector": vector}),
        409,
        "attribute_vector",
    )
    assert client.delete(f"/v1/classes/{cid}").status_code == 202
    r = client.post("/v1/classes", json={"name": "cup", "attribute_vector": vector})
    assert r.status_code == 202 and r.json()["class"]["id"] != cid


def test_training_data_cannot_be_withdrawn(client, app):
    with app.state.service.sessions() as s:
        cls = s.scalar(select(ObjectClass).where(ObjectClass.origin == "dataset").limit(1))
        sid = s.scalar(select(Sample.id).where(Sample.class_id == cls.id).limit(1))
    body = problem(client.delete(f"/v1/classes/{cls.id}"), 409, "class_id")
    assert "training dataset" in body["detail"]
    body = problem(client.delete(f"/v1/classes/{cls.id}/samples/{sid}"), 409, "sample_id")
    assert "training dataset" in body["detail"]
    with app.state.service.sessions() as s:  # nothing was marked, nothing queued
        assert s.get(ObjectClass, cls.id).withdrawn_at is None
        assert s.get(Sample, sid).withdrawn_at is None
        assert s.scalar(select(Job.id).limit(1)) is None


def test_unknown_ids_and_a_sample_of_another_class_are_404(client, dataset):
    a, sid = enrol(client, dataset, "a", 0)
    b, _ = enrol(client, dataset, "b", 1)
    problem(client.delete("/v1/classes/999999"), 404, "class_id")
    problem(client.delete(f"/v1/classes/999999/samples/{sid}"), 404, "class_id")
    problem(client.delete(f"/v1/classes/{a}/samples/999999"), 404, "sample_id")
    problem(client.delete(f"/v1/classes/{b}/samples/{sid}"), 404, "sample_id")
    problem(client.delete("/v1/classes/0"), 422, "class_id")
    assert client.get(f"/v1/classes/{a}").json()["n_samples"] == 1


def test_a_retried_withdrawal_with_its_key_gets_the_first_answer(client, app, dataset):
    cid, sid = enrol(client, dataset)
    headers = {"Idempotency-Key": "withdraw-1"}
    first = client.delete(f"/v1/classes/{cid}/samples/{sid}", headers=headers)
    again = client.delete(f"/v1/classes/{cid}/samples/{sid}", headers=headers)
    assert first.status_code == again.status_code == 202
    assert again.json() == first.json() and again.headers["Idempotent-Replayed"] == "true"
    with app.state.service.sessions() as s:
        kinds = list(s.scalars(select(Job.kind).where(Job.kind == "withdraw_sample")))
    assert kinds == ["withdraw_sample"]


def test_withdrawals_are_counted_in_the_metrics(client, dataset):
    cid, sid = enrol(client, dataset)
    client.delete(f"/v1/classes/{cid}/samples/{sid}")
    client.delete(f"/v1/classes/{cid}")
    text = client.get("/metrics").text
    assert 'tactile_withdrawals_total{kind="sample"} 1.0' in text
    assert 'tactile_withdrawals_total{kind="class"} 1.0' in text
