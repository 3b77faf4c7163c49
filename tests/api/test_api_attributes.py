"""The vocabulary grows on a running service: POST /v1/attributes adds an attribute with its
values, the model learns it, classes are described with it (graded and not-known values
too), dataset classes get values for it, DELETE retires it; bad requests are refused whole.
On SQLite and PostgreSQL, with the service's default method (``best``)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from app.store import repo
from app.store.models import Attribute, Job
from tests.service_fixtures import problem, wait_for_job


@pytest.fixture
def service(best_stores_service):
    return best_stores_service


def names(client) -> list[str]:
    return client.get("/v1/attributes").json()["attributes"]


def class_id(client, name: str) -> int:
    rows = client.get("/v1/classes", params={"limit": 1000}).json()["classes"]
    return next(c["id"] for c in rows if c["name"] == name)


def described(client, samples) -> dict[str, float]:
    r = client.post("/v1/describe", json={"samples": np.asarray(samples).tolist()})
    assert r.status_code == 200, r.text
    return {a["name"]: a["probability"] for a in r.json()["results"][0]["attributes"]}


def test_an_added_attribute_is_listed_at_once_and_learnt_when_its_job_succeeds(service, best_base):
    client, app, worker = service
    _, dataset = best_base
    before = names(client)
    touches = {"samples": dataset.samples[:5].tolist()}
    answered_before = client.post("/v1/recognize", json=touches).json()["results"]
    objects = list(dataset.class_names)
    values = {objects[0]: 1, objects[1]: 0, objects[2]: 0.5, objects[3]: 1, objects[4]: 0}
    r = client.post("/v1/attributes", json={"name": "sticky", "values": values})
    assert r.status_code == 202, r.text
    body = r.json()
    assert body["attribute"]["name"] == "sticky" and body["attribute"]["origin"] == "enrolled"
    job = body["job"]
    assert job["kind"] == "add_attribute" and job["class_id"] is None
    assert job["attribute_id"] is not None and r.headers["location"] == f"/v1/jobs/{job['id']}"
    assert names(client) == before + ["sticky"]  # at once, after the existing ones
    first = client.get(f"/v1/classes/{class_id(client, objects[0])}").json()
    assert first["attribute_values"]["sticky"] == 1.0
    untold = client.get(f"/v1/classes/{class_id(client, objects[7])}").json()
    assert "sticky" not in untold["attribute_values"]  # not known, not 0
    sample = dataset.samples[dataset.labels == 0][:1]
    assert "sticky" not in described(client, sample)  # the served model has not learnt it yet

    worker.run_once()
    done = wait_for_job(client, job["id"])
    assert done["status"] == "succeeded", done
    active = client.get("/v1/models/active").json()
    assert active["version"] == done["model_version"]
    assert active["attribute_names"] == before + ["sticky"]
    assert active["reason"] == "update"
    probability = described(client, sample)["sticky"]
    assert 0 <= probability <= 1
    # only the attribute parts were refitted: the known classes answer as before, bit for bit
    r = client.post("/v1/recognize", json=touches)
    assert r.status_code == 200 and r.json()["results"] == answered_before
    with app.state.service.sessions() as s:
        metrics = repo.active_version(s).metrics
    assert metrics["n_attributes"] == len(before) + 1


def test_a_class_is_described_with_the_new_attribute_graded_and_partly_unknown(service):
    client, _, worker = service
    client.post("/v1/attributes", json={"name": "sticky"})
    vocabulary = names(client)
    r = client.post(
        "/v1/classes", json={"name": "tape", "attributes": {"sticky": 1, vocabulary[0]: 0.5}}
    )
    assert r.status_code == 202, r.text
    cls = r.json()["class"]
    assert cls["attribute_values"] == {"sticky": 1.0, vocabulary[0]: 0.5}
    assert cls["attributes"] == [vocabulary[0], "sticky"]
    vector = [None] * len(vocabulary)
    vector[1], vector[-1] = 0.25, 1
    r = client.post("/v1/classes", json={"name": "glue", "attribute_vector": vector})
    assert r.status_code == 202, r.text
    worker.run_once()
    jobs = client.get("/v1/jobs", params={"limit": 100}).json()["jobs"]
    assert {j["status"] for j in jobs} == {"succeeded"}, jobs
    served = client.get("/v1/models/active").json()
    assert {"tape", "glue"} <= {c["name"] for c in served["classes"]}
    assert served["attribute_names"][-1] == "sticky"


def test_a_dataset_class_gets_values_for_added_attributes_only(service, best_base):
    client, _, worker = service
    _, dataset = best_base
    client.post("/v1/attributes", json={"name": "sticky"})
    cid = class_id(client, dataset.class_names[0])
    r = client.patch(f"/v1/classes/{cid}", json={"attributes": {"sticky": 0.5}})
    assert r.status_code == 202, r.text
    assert r.json()["class"]["attribute_values"]["sticky"] == 0.5
    own = dataset.attribute_names[0]
    body = problem(
        client.patch(f"/v1/classes/{cid}", json={"attributes": {own: 1}}), 409, f"attributes.{own}"
    )
    assert "stay fixed" in body["detail"]
    problem(client.patch(f"/v1/classes/{cid}", json={"attributes": ["sticky"]}), 409, "attributes")
    worker.run_once()
    job = client.get(f"/v1/jobs/{r.json()['job']['id']}").json()
    assert job["status"] == "succeeded", job


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"name": ""}, "name"),
        ({"name": "a,b"}, "name"),
        ({"name": "tab\there"}, "name"),
        ({"name": "sticky", "values": {"no such object": 1}}, "values.no such object"),
        ({"name": "sticky", "values": {"FIRST": 1.5}}, None),
        ({"name": "sticky", "values": {"FIRST": -0.1}}, None),
        ({"name": "sticky", "extra": 1}, "extra"),
    ],
)
def test_bad_attributes_are_refused_and_nothing_is_written(service, best_base, body, field):
    client, app, _ = service
    _, dataset = best_base
    if "FIRST" in body.get("values", {}):  # a real class, a value outside [0, 1]
        body = {**body, "values": {dataset.class_names[0]: body["values"]["FIRST"]}}
    before = names(client)
    problem(client.post("/v1/attributes", json=body), 422, field)
    assert names(client) == before
    with app.state.service.sessions() as s:
        assert s.query(Job).count() == 0
        assert s.query(Attribute).count() == len(before)


def test_a_name_in_use_or_retired_is_a_conflict(service, best_base):
    client, _, worker = service
    _, dataset = best_base
    problem(client.post("/v1/attributes", json={"name": dataset.attribute_names[0]}), 409, "name")
    assert client.post("/v1/attributes", json={"name": "sticky"}).status_code == 202
    problem(client.post("/v1/attributes", json={"name": "sticky"}), 409, "name")
    assert client.delete("/v1/attributes/sticky").status_code == 202
    body = problem(client.post("/v1/attributes", json={"name": "sticky"}), 409, "name")
    assert "never reused" in body["detail"]
    problem(client.delete("/v1/attributes/sticky"), 409, "name")
    problem(client.delete("/v1/attributes/glowing"), 404, "name")


def test_an_idempotency_key_replays_the_first_answer(service):
    client, app, _ = service
    headers = {"Idempotency-Key": "add-sticky-1"}
    first = client.post("/v1/attributes", json={"name": "sticky"}, headers=headers)
    again = client.post("/v1/attributes", json={"name": "sticky"}, headers=headers)
    assert first.status_code == again.status_code == 202
    assert again.json() == first.json() and again.headers["idempotent-replayed"] == "true"
    other = client.post("/v1/attributes", json={"name": "warm"}, headers=headers)
    problem(other, 422, "Idempotency-Key")
    with app.state.service.sessions() as s:
        assert s.query(Job).count() == 1


def test_retiring_leaves_new_models_and_old_versions_keep_it(service, best_base):
    client, _, worker = service
    _, dataset = best_base
    client.post("/v1/attributes", json={"name": "sticky", "values": {dataset.class_names[0]: 1}})
    worker.run_once()
    with_it = client.get("/v1/models/active").json()
    assert with_it["attribute_names"][-1] == "sticky"
    r = client.delete("/v1/attributes/sticky")
    assert r.status_code == 202, r.text
    assert "sticky" not in names(client)
    listed = {a["name"]: a for a in client.get("/v1/attributes").json()["vocabulary"]}
    assert listed["sticky"]["retired_at"] is not None
    problem(
        client.post("/v1/classes", json={"name": "tape", "attributes": {"sticky": 1}}),
        422,
        "attributes",
    )
    worker.run_once()
    assert client.get(f"/v1/jobs/{r.json()['job']['id']}").json()["status"] == "succeeded"
    without = client.get("/v1/models/active").json()
    assert "sticky" not in without["attribute_names"]
    old = client.get(f"/v1/models/{with_it['version']}").json()
    assert old["attribute_names"][-1] == "sticky"  # the old version keeps its vocabulary
    # a rollback answers with the old vocabulary
    r = client.post(f"/v1/models/{with_it['version']}/activate")
    assert r.status_code == 200, r.text
    sample = dataset.samples[:1]
    deadline = time.monotonic() + 10  # each process picks the activated version up
    while "sticky" not in described(client, sample) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert "sticky" in described(client, sample)


def test_retiring_is_refused_while_two_classes_would_look_the_same(service):
    client, _, _ = service
    client.post("/v1/attributes", json={"name": "sticky"})
    first = names(client)[0]
    for name, sticky in (("tape", 1), ("paper", 0)):
        r = client.post(
            "/v1/classes", json={"name": name, "attributes": {first: 1, "sticky": sticky}}
        )
        assert r.status_code == 202, r.text
    body = problem(client.delete("/v1/attributes/sticky"), 409, "name")
    assert "'tape' and 'paper'" in body["detail"] or "'paper' and 'tape'" in body["detail"]
    assert "sticky" in names(client)


def test_adding_attributes_takes_an_admin_key(service):
    client, app, _ = service
    with app.state.service.sessions.begin() as s:
        enroll, _ = repo.create_api_key(s, "enroll", None)
        admin, _ = repo.create_api_key(s, "admin", None)
    app.state.service.keys.refresh()
    problem(
        client.post("/v1/attributes", json={"name": "sticky"}, headers={"X-API-Key": enroll}),
        403,
        "X-API-Key",
    )
    r = client.post("/v1/attributes", json={"name": "sticky"}, headers={"X-API-Key": admin})
    assert r.status_code == 202, r.text
    problem(client.delete("/v1/attributes/sticky", headers={"X-API-Key": enroll}), 403, "X-API-Key")


def test_a_name_with_a_slash_can_be_retired(service):
    """Found by bench/fuzz.py (2026-11-24): an attribute may be named with a '/', and
    DELETE /v1/attributes/{name} answered such a name with the router's bare 404 (before
    the key was even checked), so it could never be retired."""
    client, _, _ = service
    assert client.post("/v1/attributes", json={"name": "wet/dry"}).status_code == 202
    r = client.delete("/v1/attributes/wet%2Fdry")  # as a client encodes the path parameter
    assert r.status_code == 202, r.text
    assert r.json()["attribute"]["name"] == "wet/dry"
    assert "wet/dry" not in names(client)
    problem(client.delete("/v1/attributes/wet/dry"), 409, "name")  # already retired
    problem(client.delete("/v1/attributes/no/such/thing"), 404, "name")
