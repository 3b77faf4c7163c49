"""Bodies on the wire: each POST takes only the media types it documents (415 otherwise),
and a malformed body gets a short 422 that a person can read."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.testing.service import names_of, unused_vectors
from tests.service_fixtures import npy, problem, register


def _json_body(dataset) -> dict[str, str]:
    vector = unused_vectors(dataset, 1)[0]
    return {
        "/v1/recognize": json.dumps({"samples": dataset.samples[:1].tolist()}),
        "/v1/describe": json.dumps({"samples": dataset.samples[:1].tolist()}),
        "/v1/classes": json.dumps({"name": "kettle", "attributes": names_of(vector, dataset)}),
    }


@pytest.mark.parametrize(
    "content_type",
    [
        "text/plain",
        "application/x-www-form-urlencoded",
        "application/xml",
        "multipart/form-data",
        "application/problem+json",
    ],
)
@pytest.mark.parametrize("path", ["/v1/recognize", "/v1/describe", "/v1/classes"])
def test_a_json_body_under_another_media_type_is_415(client, dataset, path, content_type):
    body = _json_body(dataset)[path]
    r = client.post(path, content=body, headers={"Content-Type": content_type})
    found = problem(r, 415, "Content-Type")
    assert content_type in found["detail"] and "application/json" in found["detail"]
    assert ("application/x-npy" in found["detail"]) == (path != "/v1/classes")
    assert client.get("/v1/classes").json()["classes"][-1]["name"] != "kettle"  # nothing written


def test_a_body_without_a_content_type_is_415(client, dataset):
    body = _json_body(dataset)["/v1/recognize"].encode()
    r = client.post("/v1/recognize", content=body)  # raw bytes: httpx sets no Content-Type
    assert "content-type" not in r.request.headers
    found = problem(r, 415, "Content-Type")
    assert "no Content-Type" in found["detail"]


def test_json_with_parameters_and_any_case_is_accepted(client, dataset):
    body = _json_body(dataset)["/v1/recognize"]
    r = client.post(
        "/v1/recognize", content=body, headers={"Content-Type": "Application/JSON; charset=utf-8"}
    )
    assert r.status_code == 200, r.text


def test_the_write_routes_check_their_media_type(client, dataset, sample):
    created = register(client, dataset, "jug")
    class_id = created["class"]["id"]
    for method, path, body in (
        ("POST", f"/v1/classes/{class_id}/samples", {"sample": sample}),
        ("PATCH", f"/v1/classes/{class_id}", {"attributes": created["class"]["attributes"]}),
    ):
        r = client.request(
            method, path, content=json.dumps(body), headers={"Content-Type": "text/plain"}
        )
        assert "application/json" in problem(r, 415, "Content-Type")["detail"]
    r = client.post(
        f"/v1/classes/{class_id}/samples",
        content=npy(np.asarray(sample)),
        headers={"Content-Type": "application/x-npy"},
    )
    problem(r, 415, "Content-Type")


def test_a_batch_of_strings_is_one_short_problem(client, dataset):
    """Every value a string: one problem, with its count, not an error per value."""
    strings = np.full((3, *dataset.input_shape), "a").tolist()
    r = client.post("/v1/recognize", json={"samples": strings})
    found = problem(r, 422)
    assert len(r.content) < 1000
    n = int(np.prod(dataset.input_shape)) * 3
    assert found["errors"] == [
        {"field": "samples[0][0][0]", "reason": f'not a number (got "a"); {n - 1} more like it'}
    ]


def test_each_distinct_problem_is_named_once_without_internal_names(client, dataset):
    samples = dataset.samples[:2].tolist()
    samples[0][1][2] = "x"
    samples[1][0][0] = [1.0]
    samples[1][3][4] = None
    r = client.post("/v1/recognize", json={"samples": samples, "extra": 1})
    found = problem(r, 422)
    fields = {e["field"]: e["reason"] for e in found["errors"]}
    # one problem per reason and place in a sample, named where it first occurs
    assert fields == {
        "samples[0][1][2]": 'not a number (got "x"); 2 more like it',
        "extra": "not a field of this request",
    }, found
    assert "list[" not in r.text and "float]" not in r.text


def test_a_flat_sample_with_a_bad_value_is_named_at_its_place(client):
    r = client.post("/v1/recognize", json={"samples": [[1.0, "x", 3.0]]})
    assert problem(r, 422)["errors"] == [
        {"field": "samples[0][1]", "reason": 'not a number (got "x")'}
    ]


def test_the_errors_are_at_most_a_handful(client, dataset):
    # six different fields wrong: five named
    r = client.post("/v1/classes", json={"nmae": 1, "a": 1, "b": 2, "c": 3, "d": 4, "e": 5})
    assert len(problem(r, 422)["errors"]) == 5


@pytest.mark.parametrize(
    "bad, got",
    [
        (lambda s: s[:3], "got one of shape [3, "),
        (lambda s: s[0], "got one of shape ["),
    ],
)
def test_a_single_sample_route_names_the_shape_of_one_sample(client, dataset, sample, bad, got):
    class_id = register(client, dataset, "cup")["class"]["id"]
    r = client.post(f"/v1/classes/{class_id}/samples", json={"sample": bad(sample)})
    found = problem(r, 422, "sample")
    assert found["detail"].startswith(
        f"sample: expected one sample of shape {list(dataset.input_shape)}, {got}"
    )
    assert "(N" not in found["detail"]


def test_a_batch_sent_as_one_sample_is_told_the_shape_of_one(client, dataset, sample):
    class_id = register(client, dataset, "mug")["class"]["id"]
    found = problem(
        client.post(f"/v1/classes/{class_id}/samples", json={"sample": [sample, sample]}),
        422,
        "sample",
    )
    assert found["detail"] == (
        f"sample: expected one sample of shape {list(dataset.input_shape)}, got a list of 2: "
        "send them one at a time"
    )
    assert len(found["errors"]) == 1


def test_a_ragged_single_sample_names_the_shape_too(client, dataset, sample):
    class_id = register(client, dataset, "bowl")["class"]["id"]
    sample[2] = sample[2][:-1]
    found = problem(
        client.post(f"/v1/classes/{class_id}/samples", json={"sample": sample}), 422, "sample"
    )
    assert found["detail"] == (
        f"sample: expected one sample of shape {list(dataset.input_shape)}; its rows have "
        "different lengths"
    )
