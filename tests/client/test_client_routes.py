"""The client answers as the routes do: each call's return against its route's response
model, the lists page by page, and batches over the service's limit sent in parts whose
answers join in order, from one model version."""

from __future__ import annotations

import httpx
import numpy as np
import pytest

from app.api.routes.health import Liveness
from app.api.schemas import (
    AttributeChanged,
    AttributeList,
    ClassCreated,
    ClassList,
    ClassOut,
    JobList,
    JobOut,
    ModelList,
    RecognizeResponse,
    SampleCreated,
)
from app.client import ServiceError, TactileClient
from app.testing.service import list_all, unused_vectors


def fields(model) -> set[str]:
    """The JSON keys of a response model as it leaves the service (by alias: ``class``)."""
    return set(model.model_json_schema(by_alias=True, mode="serialization")["properties"])


def same_shape(answer: dict, model) -> None:
    """``answer`` has exactly the keys of the route's response model; a job in it, those of
    ``JobOut``."""
    assert set(answer) == fields(model), (set(answer), fields(model))
    if isinstance(answer.get("job"), dict):
        assert set(answer["job"]) == fields(JobOut), set(answer["job"])


def test_every_enrolment_answers_as_its_route(best_service, best_base):
    """register_class, create_class, redescribe_class, add_sample, add_attribute and
    retire_attribute return their route's body; ``wait`` reads its job again."""
    client, _, worker = best_service
    _, dataset = best_base
    robot = TactileClient(http=client, retries=0)
    vector = unused_vectors(dataset, 3)
    created = robot.register_class("cup", attribute_vector=vector[0])
    same_shape(created, ClassCreated)
    assert created["class"]["id"] == created["job"]["class_id"]
    assert created["class"]["name"] == "cup" and created["job"]["status"] == "queued"
    by_http = client.post("/v1/classes", json={"name": "bowl", "attribute_vector": vector[1]})
    assert set(by_http.json()) == set(created)  # the same shape as HTTP's own answer
    worker.run_once()

    relayed = robot.create_class({"name": "jar", "attributes": [dataset.attribute_names[0]]})
    same_shape(relayed, ClassCreated)
    worker.run_once()
    assert robot.job(relayed["job"]["id"])["status"] == "succeeded"

    redone = robot.redescribe_class(created["class"]["id"], attribute_vector=vector[2], wait=0.1)
    same_shape(redone, ClassCreated)
    assert redone["job"]["kind"] == "update_class"  # nobody ran it: still queued after the wait

    added = robot.add_sample(created["class"]["id"], dataset.samples[0])
    same_shape(added, SampleCreated)
    assert added["job"]["sample_id"] == added["sample_id"]

    attribute = robot.add_attribute("sticky", {dataset.class_names[0]: 1})
    same_shape(attribute, AttributeChanged)
    worker.run_once()  # the redescription, the sample and the attribute
    waited = robot.retire_attribute("sticky", wait=0.1)
    same_shape(waited, AttributeChanged)
    assert waited["attribute"]["name"] == "sticky"
    worker.run_once()
    assert robot.job(waited["job"]["id"], wait=2)["status"] == "succeeded"
    # wait: the job read again, done, in the shape the route gives it
    done = robot.add_sample(created["class"]["id"], dataset.samples[1], wait=0.1)
    worker.run_once()
    same_shape(robot.job(done["job"]["id"], wait=2), JobOut)
    assert robot.job(done["job"]["id"])["status"] == "succeeded"


def test_the_lists_answer_as_their_routes_page_by_page(best_service, best_base):
    client, _, worker = best_service
    _, dataset = best_base
    robot = TactileClient(http=client, retries=0)
    for i, vector in enumerate(unused_vectors(dataset, 3)):
        robot.register_class(f"thing {i}", attribute_vector=vector)
    worker.run_once()

    page = robot.classes(limit=2)
    same_shape(page, ClassList)
    assert page == client.get("/v1/classes", params={"limit": 2}).json()
    assert len(page["classes"]) == 2 and page["next_after"] is not None
    after = robot.classes(after=page["next_after"], limit=2)
    assert after["classes"][0]["id"] > page["classes"][-1]["id"]
    every = robot.every("classes")
    assert every == list_all(client, "/v1/classes", "classes")
    assert [c["name"] for c in every][-3:] == ["thing 0", "thing 1", "thing 2"]
    one = robot.get_class(every[-1]["id"])
    same_shape(one, ClassOut)
    assert one["in_active_model"] is True

    jobs = robot.jobs(kind="register_class")
    same_shape(jobs, JobList)
    assert [j["class_id"] for j in jobs["jobs"]] == [c["id"] for c in every[-3:]]
    assert robot.jobs(status="failed")["jobs"] == []
    assert robot.every("jobs", class_id=every[-1]["id"]) == jobs["jobs"][-1:]

    models = robot.models()
    same_shape(models, ModelList)
    assert models == client.get("/v1/models").json()
    assert robot.every("models") == list_all(client, "/v1/models", "models")
    assert robot.every("models")[-1]["version"] == robot.active_model()["version"]

    vocabulary = robot.attributes()
    same_shape(vocabulary, AttributeList)
    assert vocabulary == client.get("/v1/attributes").json()
    assert vocabulary["attributes"] == list(dataset.attribute_names)

    with pytest.raises(ServiceError) as refused:  # the service names the bad filter
        robot.jobs(status="lost")
    assert refused.value.status == 422 and "status" in str(refused.value)
    with pytest.raises(ValueError, match="every\\(\\) reads one of"):
        robot.every("samples")


def test_a_batch_over_the_limit_is_split_and_joined_in_order(client, app, dataset):
    """The client reads the limit from GET /healthz and sends parts under it; the joined
    answer is what one request would give."""
    x = dataset.samples[:7]
    whole = TactileClient(http=client, retries=0).recognize(x)
    app.state.service.recognition.batch_limit = 3
    sent = []
    counting = httpx.Client(
        transport=Counting(client._transport, sent), base_url=str(client.base_url)
    )
    robot = TactileClient(http=counting, retries=0)
    assert robot.batch_limit() == 3
    assert Liveness.model_validate(client.get("/healthz").json()).batch_limit == 3

    split = robot.recognize(x)
    same_shape({k: v for k, v in split.items() if k != "source"}, RecognizeResponse)
    assert sent.count("/v1/recognize") == 3  # 3 + 3 + 1
    assert split["source"] == "service" and split["model_version"] == whole["model_version"]
    assert [r["class_name"] for r in split["results"]] == [
        r["class_name"] for r in whole["results"]
    ]
    np.testing.assert_allclose(
        [r["novelty_score"] for r in split["results"]],
        [r["novelty_score"] for r in whole["results"]],
        rtol=1e-5,
    )
    # one sample alone is one request, whatever its first axis; the limit is read once
    sent.clear()
    assert dataset.samples[0].ndim == 2 and len(dataset.samples[0]) > 3
    alone = robot.recognize(dataset.samples[0])  # its rows are not samples
    assert len(alone["results"]) == 1 and sent.count("/healthz") == 0
    # touches of one object are one request: the service refuses them past its limit
    with pytest.raises(ServiceError, match="batch limit of 3") as refused:
        robot.recognize(x, same_object=True)
    assert refused.value.status == 422


def test_a_version_that_goes_live_mid_batch_answers_the_whole_batch(client, app, worker, dataset):
    """A new version activated between the parts: the earlier parts are asked again at it,
    so every result comes from one version."""
    x = dataset.samples[:5]
    app.state.service.recognition.batch_limit = 2
    TactileClient(http=client, retries=0).register_class(
        "cup", attribute_vector=unused_vectors(dataset, 1)[0]
    )
    sent: list[str] = []
    transport = Counting(client._transport, sent, after_first_recognize=worker.run_once)
    robot = TactileClient(
        http=httpx.Client(transport=transport, base_url=str(client.base_url)), retries=0
    )
    answer = robot.recognize(x)
    assert answer["model_version"] == 2 and len(answer["results"]) == 5
    assert sent.count("/v1/recognize") == 4  # parts 1, 2, 3 and part 1 again at version 2
    app.state.service.recognition.batch_limit = 1024
    at_two = TactileClient(http=client, retries=0).recognize(x)
    assert [r["class_name"] for r in answer["results"]] == [
        r["class_name"] for r in at_two["results"]
    ]


class Counting(httpx.BaseTransport):
    """Records each request's path; optionally runs ``after_first_recognize`` once the
    first recognition has been answered (a worker activating a new version then)."""

    def __init__(self, inner: httpx.BaseTransport, sent: list[str], after_first_recognize=None):
        self.inner, self.sent, self.then = inner, sent, after_first_recognize

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        response = self.inner.handle_request(request)
        self.sent.append(request.url.path)
        if request.url.path == "/v1/recognize" and self.then is not None:
            then, self.then = self.then, None
            response.read()
            assert then() == 1
        return response
