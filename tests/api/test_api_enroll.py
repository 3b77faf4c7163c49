"""POST /v1/classes and POST /v1/classes/{id}/samples, and write access by API key."""

from __future__ import annotations

import json

import numpy as np
import pytest
from sqlalchemy import select

from app.store.models import Job, ObjectClass, Sample
from app.testing.service import names_of, unused_vectors
from tests.service_fixtures import problem


@pytest.fixture
def new_vector(dataset) -> list[int]:
    return unused_vectors(dataset, 1)[0]


def test_register_by_attribute_names_is_committed_before_202(client, app, dataset, new_vector):
    names = names_of(new_vector, dataset)
    r = client.post("/v1/classes", json={"name": "mug", "attributes": names})
    assert r.status_code == 202
    body = r.json()
    cls, job = body["class"], body["job"]
    assert cls["name"] == "mug" and cls["kind"] == "novel" and cls["attributes"] == names
    assert cls["n_samples"] == 0 and cls["in_active_model"] is False
    assert (
        job["status"] == "queued"
        and job["kind"] == "register_class"
        and job["class_id"] == cls["id"]
    )
    assert r.headers["location"] == f"/v1/jobs/{job['id']}"
    with app.state.service.sessions() as s:  # a fresh session sees both rows: they are committed
        assert s.get(ObjectClass, cls["id"]).name == "mug"
        assert s.get(Job, job["id"]).status == "queued"
    assert client.get(f"/v1/jobs/{job['id']}").json()["status"] == "queued"
    assert client.get(f"/v1/classes/{cls['id']}").json()["in_active_model"] is False


def test_register_by_attribute_vector(client, dataset, new_vector):
    r = client.post("/v1/classes", json={"name": "bottle", "attribute_vector": new_vector})
    assert r.status_code == 202
    assert r.json()["class"]["attributes"] == names_of(new_vector, dataset)


def test_name_is_trimmed(client, new_vector):
    r = client.post("/v1/classes", json={"name": "  cup  ", "attribute_vector": new_vector})
    assert r.json()["class"]["name"] == "cup"


def test_unknown_attribute(client):
    body = problem(
        client.post("/v1/classes", json={"name": "x", "attributes": ["hard", "glassy"]}),
        422,
        "attributes",
    )
    assert "glassy" in body["detail"]


def test_no_attribute_set(client, dataset):
    problem(client.post("/v1/classes", json={"name": "x", "attributes": []}), 422, "attributes")
    zeros = [0] * dataset.n_attributes
    problem(
        client.post("/v1/classes", json={"name": "x", "attribute_vector": zeros}),
        422,
        "attribute_vector",
    )


def test_wrong_vector_length(client, new_vector):
    body = problem(
        client.post("/v1/classes", json={"name": "x", "attribute_vector": new_vector + [1]}),
        422,
        "attribute_vector",
    )
    assert str(len(new_vector)) in body["detail"]


def test_vector_values_must_be_bits(client, new_vector):
    bad = list(new_vector)
    bad[0] = 2
    problem(
        client.post("/v1/classes", json={"name": "x", "attribute_vector": bad}),
        422,
        "attribute_vector[0]",
    )


def test_exactly_one_description(client, dataset, new_vector):
    names = names_of(new_vector, dataset)
    problem(client.post("/v1/classes", json={"name": "x"}), 422, "body")
    problem(
        client.post(
            "/v1/classes", json={"name": "x", "attributes": names, "attribute_vector": new_vector}
        ),
        422,
        "body",
    )


def test_missing_or_empty_name(client, new_vector):
    problem(client.post("/v1/classes", json={"attribute_vector": new_vector}), 422, "name")
    problem(
        client.post("/v1/classes", json={"name": "   ", "attribute_vector": new_vector}),
        422,
        "name",
    )


def test_control_characters_in_a_name(client, new_vector):
    problem(
        client.post("/v1/classes", json={"name": "a\x00b", "attribute_vector": new_vector}),
        422,
        "name",
    )


def test_unknown_field_is_named(client, new_vector):
    problem(
        client.post(
            "/v1/classes", json={"name": "x", "attribute_vector": new_vector, "colour": "red"}
        ),
        422,
        "colour",
    )


def test_malformed_json(client):
    r = client.post(
        "/v1/classes", content=b'{"name": ', headers={"content-type": "application/json"}
    )
    assert "malformed JSON" in problem(r, 422, "body")["detail"]


def test_duplicate_name_is_409(client, dataset, new_vector):
    body = problem(
        client.post(
            "/v1/classes", json={"name": dataset.class_names[0], "attribute_vector": new_vector}
        ),
        409,
        "name",
    )
    assert "already exists" in body["detail"]


def test_duplicate_vector_of_a_known_class_is_409(client, dataset):
    vector = dataset.class_attributes[2].astype(int).tolist()
    body = problem(
        client.post("/v1/classes", json={"name": "twin", "attribute_vector": vector}),
        409,
        "attribute_vector",
    )
    assert dataset.class_names[2] in body["detail"]


def test_duplicate_vector_of_an_enrolled_class_is_409(client, dataset, new_vector):
    assert (
        client.post("/v1/classes", json={"name": "a", "attribute_vector": new_vector}).status_code
        == 202
    )
    names = names_of(new_vector, dataset)
    problem(client.post("/v1/classes", json={"name": "b", "attributes": names}), 409, "attributes")
    problem(
        client.post(
            "/v1/classes", json={"name": "a", "attribute_vector": unused_vectors(dataset, 2)[1]}
        ),
        409,
        "name",
    )


# -------------------------------------------------------------------- samples


@pytest.fixture
def novel_class(client, new_vector) -> int:
    return client.post(
        "/v1/classes", json={"name": "novel", "attribute_vector": new_vector}
    ).json()["class"]["id"]


def test_add_sample_is_committed_before_202(client, app, novel_class, sample):
    r = client.post(f"/v1/classes/{novel_class}/samples", json={"sample": sample})
    assert r.status_code == 202
    body = r.json()
    assert body["job"]["kind"] == "add_sample" and body["job"]["sample_id"] == body["sample_id"]
    with app.state.service.sessions() as s:
        row = s.get(Sample, body["sample_id"])
        assert row.class_id == novel_class and row.origin == "enrolled"
        stored = np.frombuffer(row.data, np.float32).reshape(row.shape)
        assert np.array_equal(stored, np.asarray(sample, np.float32))
    assert client.get(f"/v1/classes/{novel_class}").json()["n_samples"] == 1


def test_the_answer_says_what_the_served_model_made_of_the_sample(
    client, novel_class, sample, dataset
):
    """A sample of a known object enrolled into a novel class by mistake is named for what it is."""
    body = client.post(f"/v1/classes/{novel_class}/samples", json={"sample": sample}).json()
    served = client.post("/v1/recognize", json={"samples": [sample]}).json()
    assert body["model_version"] == served["model_version"] == 1
    assert (
        body["recognized_as"] == served["results"][0]
    )  # before learning from it: as recognize says
    assert body["recognized_as"]["class_name"] == dataset.class_names[0]  # the sample's own object
    assert body["recognized_as"]["is_novel"] is False


def test_sample_wrong_shape(client, novel_class, sample):
    problem(
        client.post(f"/v1/classes/{novel_class}/samples", json={"sample": sample[:-1]}),
        422,
        "sample",
    )
    problem(
        client.post(
            f"/v1/classes/{novel_class}/samples", json={"sample": [row[:-1] for row in sample]}
        ),
        422,
        "sample",
    )
    problem(
        client.post(f"/v1/classes/{novel_class}/samples", json={"sample": sample[0]}), 422, "sample"
    )


def test_sample_ragged(client, novel_class, sample):
    sample[3] = sample[3][:2]
    problem(
        client.post(f"/v1/classes/{novel_class}/samples", json={"sample": sample}), 422, "sample"
    )


def test_sample_nan_by_json_literal(client, novel_class, sample):
    sample[2][2] = "__BAD__"
    raw = json.dumps({"sample": sample}).replace('"__BAD__"', "NaN")
    r = client.post(
        f"/v1/classes/{novel_class}/samples",
        content=raw,
        headers={"content-type": "application/json"},
    )
    assert "NaN" in problem(r, 422, "sample")["detail"]


def test_sample_for_unknown_class_is_404(client, sample):
    problem(client.post("/v1/classes/777777/samples", json={"sample": sample}), 404, "class_id")


def test_sample_for_known_class_is_409(client, sample):
    problem(client.post("/v1/classes/1/samples", json={"sample": sample}), 409, "class_id")


def test_sample_missing_field(client, novel_class, sample):
    url = f"/v1/classes/{novel_class}/samples"
    problem(client.post(url, json={"samples": [sample]}), 422, "samples")  # misspelt
    found = problem(client.post(url, json={}), 422, "body")
    assert found["errors"] == [
        {"field": "body", "reason": "give exactly one of 'sample' or 'trial'"}
    ]


def test_rejected_writes_store_nothing(client, app, novel_class, sample):
    with app.state.service.sessions() as s:
        before = (len(s.scalars(select(Sample.id)).all()), len(s.scalars(select(Job.id)).all()))
    client.post(f"/v1/classes/{novel_class}/samples", json={"sample": sample[:-1]})
    client.post("/v1/classes", json={"name": "x", "attributes": ["nope"]})
    with app.state.service.sessions() as s:
        after = (len(s.scalars(select(Sample.id)).all()), len(s.scalars(select(Job.id)).all()))
    assert after == before


# ---------------------------------------------------------------- API keys


def test_keys_from_the_environment_are_admin_keys(client, app, new_vector, sample):
    app.state.service.keys.set_env_keys(["k1", "k2"])
    body = {"name": "locked", "attribute_vector": new_vector}
    problem(client.post("/v1/classes", json=body), 401, "X-API-Key")
    problem(client.post("/v1/classes", json=body, headers={"X-API-Key": "wrong"}), 401, "X-API-Key")
    problem(client.post("/v1/models/1/activate"), 401, "X-API-Key")
    problem(client.post("/v1/classes/1/samples", json={"sample": sample}), 401, "X-API-Key")
    # once a key exists, reads and recognition need one too
    problem(client.get("/v1/classes"), 401, "X-API-Key")
    problem(client.post("/v1/recognize", json={"samples": [sample]}), 401, "X-API-Key")
    k2 = {"X-API-Key": "k2"}
    assert client.post("/v1/classes", json=body, headers=k2).status_code == 202
    assert client.get("/v1/classes", headers=k2).status_code == 200
    assert client.post("/v1/recognize", json={"samples": [sample]}, headers=k2).status_code == 200
    assert client.post("/v1/models/1/activate", headers=k2).status_code == 200


def test_keys_from_the_environment_are_comma_separated(monkeypatch):
    from app.config import Settings

    monkeypatch.setenv("TACTILE_API_KEYS", "alpha, beta ,")
    assert Settings().api_keys == ["alpha", "beta"]
