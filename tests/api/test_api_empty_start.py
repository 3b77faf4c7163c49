"""A service started without a dataset (``--dataset none``): no classes, no attributes, no
model; recognition says what is missing until classes have samples, the worker then trains
the first model from them, with the attributes added through the API. On both stores."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.data.simulator import simulate_dataset
from app.testing.service import BEST_PARAMS
from tests.service_fixtures import problem


@pytest.fixture
def empty(settings):
    """(client, worker) of a ``best`` service on an empty store."""
    from app.api.main import create_app
    from worker import Worker

    app = create_app(
        settings.model_copy(
            update={"dataset": "none", "method": "best", "method_params": {"best": BEST_PARAMS}}
        )
    )
    with TestClient(app) as client:
        state = app.state.service
        yield client, Worker(state.settings, state.sessions, on_activate=state.holder.serve)


@pytest.fixture(scope="module")
def touches():
    return simulate_dataset(n_objects=3, trials_per_object=4, seed=5)


def samples_of(touches, k: int, n: int) -> list:
    return touches.samples[touches.labels == k][:n].tolist()


def test_an_empty_service_recognises_once_its_first_classes_have_samples(empty, touches):
    client, worker = empty
    assert client.get("/v1/attributes").json()["attributes"] == []
    assert client.get("/v1/classes").json()["classes"] == []
    one = touches.samples[:1].tolist()
    body = problem(client.post("/v1/recognize", json={"samples": one}), 409, "model")
    assert "2 classes have at least 2 samples each (0 so far)" in body["detail"]
    problem(client.post("/v1/describe", json={"samples": one}), 409, "model")

    assert client.post("/v1/attributes", json={"name": "soft"}).status_code == 202
    r = client.post(
        "/v1/classes",
        json={"name": "sponge", "samples": samples_of(touches, 0, 3), "attributes": {"soft": 1}},
    )
    assert r.status_code == 202, r.text
    assert worker.run_once() == 0  # one class is not enough: the jobs wait
    body = problem(client.post("/v1/recognize", json={"samples": one}), 409, "model")
    assert "(1 so far)" in body["detail"]
    jobs = client.get("/v1/jobs").json()["jobs"]
    assert {j["status"] for j in jobs} == {"queued"}

    r = client.post("/v1/classes", json={"name": "stone", "samples": samples_of(touches, 1, 2)})
    assert r.status_code == 202, r.text
    r = client.post("/v1/classes", json={"name": "pillow", "attributes": {"soft": 0.8}})
    assert r.status_code == 202, r.text  # zero-shot: a novel class of the first model
    assert worker.run_once() > 0
    jobs = client.get("/v1/jobs", params={"limit": 100}).json()["jobs"]
    assert {j["status"] for j in jobs} == {"succeeded"}, jobs
    active = client.get("/v1/models/active").json()
    assert active["reason"] == "bootstrap" and active["attribute_names"] == ["soft"]
    kinds = {c["name"]: c["kind"] for c in active["classes"]}
    assert kinds == {"sponge": "known", "stone": "known", "pillow": "novel"}

    r = client.post("/v1/recognize", json={"samples": samples_of(touches, 0, 4)})
    assert r.status_code == 200, r.text
    answers = [res["class_name"] for res in r.json()["results"]]
    assert answers.count("sponge") >= 3, answers
    r = client.post("/v1/describe", json={"samples": samples_of(touches, 0, 1)})
    assert r.status_code == 200 and r.json()["results"][0]["attributes"][0]["name"] == "soft"

    # a word added later is learnt; the first model's known classes stay known (they have
    # fewer samples than the promotion threshold, and need not)
    r = client.post("/v1/attributes", json={"name": "cold", "values": {"stone": 1, "sponge": 0}})
    worker.run_once()
    assert client.get(f"/v1/jobs/{r.json()['job']['id']}").json()["status"] == "succeeded"
    active = client.get("/v1/models/active").json()
    assert active["attribute_names"] == ["soft", "cold"]
    assert {c["name"]: c["kind"] for c in active["classes"]} == kinds


def test_samples_before_a_model_must_share_one_shape(empty, touches):
    client, _ = empty
    first = samples_of(touches, 0, 2)
    assert client.post("/v1/classes", json={"name": "a", "samples": first}).status_code == 202
    flat = np.zeros(7).tolist()
    body = problem(
        client.post("/v1/classes", json={"name": "b", "samples": [flat]}), 422, "samples[0]"
    )
    assert "shape" in body["detail"]
    problem(
        client.post("/v1/classes", json={"name": "c", "samples": [[[1.0, 2.0], [1.0]]]}),
        422,
        "samples[0]",
    )
    problem(
        client.post("/v1/classes", json={"name": "d", "attributes": ["soft"]}), 409, "attributes"
    )
