"""The robot's client (app/client.py) against the real API app: it keeps the model file
current, answers offline when the service is unreachable, and never enrols twice."""

from __future__ import annotations

import json

import httpx
import numpy as np
import pytest

from app.client import ServiceError, ServiceUnreachable, TactileClient
from app.framework import bundle
from app.testing.harness import free_port
from app.testing.service import list_all, unused_vectors
from tests.service_fixtures import live_channel


@pytest.fixture
def robot(client, tmp_path):
    return TactileClient(
        http=client, model_file=tmp_path / "robot" / "model.bundle", retries=0, timeout=2
    )


def unreachable(tmp_path, **kwargs) -> TactileClient:
    """A client of a port nobody listens on: every request fails to connect."""
    return TactileClient(
        f"http://127.0.0.1:{free_port()}",
        model_file=tmp_path / "robot" / "model.bundle",
        timeout=2,
        **kwargs,
    )


def test_the_model_file_follows_the_active_version(robot, client, worker, dataset):
    assert robot.sync_model() is True
    assert robot.sync_model() is False  # 304: nothing downloaded
    meta = json.loads(robot.model_file.with_name("model.bundle.json").read_text())
    assert meta["version"] == 1 and meta["etag"]
    job = robot.register_class("cup", attribute_vector=unused_vectors(dataset, 1)[0])["job"]
    assert worker.run_once() == 1
    assert robot.job(job["id"], wait=2)["status"] == "succeeded"
    assert robot.sync_model() is True
    meta = json.loads(robot.model_file.with_name("model.bundle.json").read_text())
    assert meta["version"] == 2 and meta["class_ids"]["cup"] == job["class_id"]
    client.post("/v1/models/1/activate")  # a rollback reaches the robot too
    assert robot.sync_model() is True
    assert json.loads(robot.model_file.with_name("model.bundle.json").read_text())["version"] == 1


def test_offline_answers_are_the_services_answers(robot, client, worker, dataset, tmp_path):
    job = robot.register_class("cup", attribute_vector=unused_vectors(dataset, 1)[0])["job"]
    worker.run_once()
    robot.sync_model()
    x = dataset.samples[::9][:6]
    online = robot.recognize(x)
    offline = unreachable(tmp_path, retries=1).recognize(x)
    assert online["source"] == "service" and offline["source"] == "offline"
    assert offline["model_version"] == online["model_version"] == 2
    for a, b in zip(offline["results"], online["results"], strict=True):
        assert (a["class_id"], a["class_name"], a["is_novel"]) == (
            b["class_id"],
            b["class_name"],
            b["is_novel"],
        )
        np.testing.assert_allclose(a["novelty_score"], b["novelty_score"], rtol=1e-5)
    assert all(s["class_id"] is not None for r in offline["results"] for s in r["top_k"])
    assert (
        robot._meta()["class_ids"]["cup"] == job["class_id"]
    )  # the store's id of the enrolled class


def test_without_a_model_file_an_outage_is_a_clear_error(tmp_path, sample):
    with (
        unreachable(tmp_path, retries=0) as robot,
        pytest.raises(ServiceUnreachable, match="no model file to recognise offline"),
    ):
        robot.recognize(sample)
    assert robot.http.is_closed


def test_a_model_file_without_its_sidecar_still_answers(robot, dataset, tmp_path):
    robot.sync_model()
    robot.model_file.with_name("model.bundle.json").write_text("{}")
    answer = unreachable(tmp_path, retries=0).recognize(dataset.samples[:2])
    assert answer["source"] == "offline" and answer["model_version"] is None
    assert all(r["class_id"] is None and r["class_name"] for r in answer["results"])


def test_refused_input_is_an_error_not_an_offline_answer(robot, sample):
    robot.sync_model()
    bad = np.asarray(sample, np.float32)
    bad[0, 0] = np.nan
    with pytest.raises(ServiceError, match="422") as caught:
        robot.recognize(bad)
    assert caught.value.status == 422 and not isinstance(caught.value, ServiceUnreachable)
    with pytest.raises(ServiceError, match="404"):
        robot.add_sample(99999, sample)


class LoseFirstAnswer(httpx.BaseTransport):
    """The network loses the first answer after the service has acted on the request."""

    def __init__(self, inner: httpx.BaseTransport) -> None:
        self.inner, self.lost = inner, 0

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        response = self.inner.handle_request(request)
        if self.lost == 0:
            self.lost += 1
            response.read()
            raise httpx.ReadTimeout("the answer was lost", request=request)
        return response


def test_a_retry_after_a_lost_answer_enrols_once(client, worker, dataset, sample):
    flaky = httpx.Client(
        transport=LoseFirstAnswer(client._transport), base_url=str(client.base_url)
    )
    robot = TactileClient(http=flaky, retries=2)
    job = robot.register_class("teapot", attribute_vector=unused_vectors(dataset, 1)[0])["job"]
    assert robot.http._transport.lost == 1
    assert [c["name"] for c in list_all(client, "/v1/classes", "classes")].count("teapot") == 1
    worker.run_once()
    assert client.get(f"/v1/jobs/{job['id']}").json()["status"] == "succeeded"
    robot.http._transport.lost = 0  # lose the next answer too
    added = robot.add_sample(job["class_id"], sample)
    assert client.get(f"/v1/classes/{job['class_id']}").json()["n_samples"] == 1
    assert added["job"]["sample_id"] == added["sample_id"] and added["recognized_as"]["class_name"]
    np.testing.assert_array_equal(
        robot.sample(job["class_id"], added["sample_id"]), np.float32(sample)
    )
    worker.run_once()
    done = robot.add_sample(job["class_id"], sample, wait=0.5)  # nobody runs this job: still queued
    assert done["job"]["status"] == "queued" and done["job"]["sample_id"] == done["sample_id"]


def test_bad_client_settings_are_refused(tmp_path):
    with pytest.raises(ValueError, match="retries"):
        TactileClient("http://127.0.0.1:1", retries=-1)
    with pytest.raises(ValueError, match="no model_file"):
        TactileClient("http://127.0.0.1:1").sync_model()
    with pytest.raises(ValueError, match="description, samples or trials"):
        TactileClient("http://127.0.0.1:1").register_class("x")
    with pytest.raises(ValueError, match="attributes or attribute_vector, not both"):
        TactileClient("http://127.0.0.1:1").redescribe_class(1, ["hard"], [1, 0])


def test_a_class_described_anew_reaches_the_model_file(robot, worker, dataset):
    job = robot.register_class("cup", attribute_vector=unused_vectors(dataset, 1)[0])["job"]
    worker.run_once()
    vector = unused_vectors(dataset, 2)[1]
    update = robot.redescribe_class(job["class_id"], attribute_vector=vector)["job"]
    assert update["kind"] == "update_class" and update["status"] == "queued"
    worker.run_once()
    assert robot.job(update["id"])["status"] == "succeeded"
    assert robot.sync_model() is True
    reg = bundle.load(robot.model_file).registry
    assert reg.novel_attributes[reg.novel_names.index("cup")].tolist() == vector


def test_a_touch_is_described_for_the_operator(best_service, best_base):
    client, _, _ = best_service
    _, dataset = best_base
    robot = TactileClient(http=client, retries=0)
    answer = robot.describe(dataset.samples[:2])
    assert (
        answer == client.post("/v1/describe", json={"samples": dataset.samples[:2].tolist()}).json()
    )
    assert len(answer["results"]) == 2 and answer["results"][0]["suggested"]


def test_touches_of_one_object_get_one_answer_online_and_offline(robot, dataset, tmp_path):
    robot.sync_model()
    touches = dataset.samples[dataset.labels == 3][:3]
    online = robot.recognize(touches, same_object=True)
    offline = unreachable(tmp_path, retries=0).recognize(touches, same_object=True)
    assert len(online["results"]) == len(offline["results"]) == 1
    assert online["results"][0]["class_name"] == offline["results"][0]["class_name"]
    np.testing.assert_allclose(
        online["results"][0]["novelty_score"], offline["results"][0]["novelty_score"], rtol=1e-5
    )
    assert len(robot.recognize(touches)["results"]) == 3


def test_an_operator_adds_an_attribute_and_describes_a_class_with_it(best_service, best_base):
    client, _, worker = best_service
    _, dataset = best_base
    robot = TactileClient(http=client, retries=0)
    job = robot.add_attribute("sticky", {dataset.class_names[0]: 1, dataset.class_names[1]: 0.5})
    assert job["attribute"]["name"] == "sticky"
    job = job["job"]
    assert job["kind"] == "add_attribute" and job["status"] == "queued"
    registered = robot.register_class("tape", attributes={"sticky": 1})["job"]
    with pytest.raises(ServiceError, match="409.*'tape' described by nothing"):
        robot.retire_attribute("sticky")  # tape would be described by nothing
    robot.redescribe_class(registered["class_id"], attributes={dataset.attribute_names[0]: 1})
    worker.run_once()
    assert robot.job(job["id"])["status"] == robot.job(registered["id"])["status"] == "succeeded"
    touch = robot.describe(dataset.samples[:1])["results"][0]["attributes"]
    assert "sticky" in {a["name"] for a in touch}
    with pytest.raises(ServiceError, match="409.*never reused|409.*exists"):
        robot.add_attribute(dataset.attribute_names[0])
    retired = robot.retire_attribute("sticky")
    assert retired["job"]["kind"] == "retire_attribute" and retired["attribute"]["name"] == "sticky"


def test_an_operator_describes_an_object_in_words(best_service):
    client, _, worker = best_service
    robot = TactileClient(http=client, retries=0)
    read = robot.interpret("slightly rough and not hard")
    assert read["values"]["rough"] == 0.6 and read["values"]["hard"] == 0.0
    job = robot.register_class("mat", description="a thick, bumpy rubber mat")["job"]
    worker.run_once()
    assert robot.job(job["id"])["status"] == "succeeded"
    redo = robot.redescribe_class(job["class_id"], description="a thin bumpy mat")["job"]
    worker.run_once()
    assert robot.job(redo["id"])["status"] == "succeeded"
    cls = client.get(f"/v1/classes/{job['class_id']}").json()
    assert cls["description"] == "a thin bumpy mat" and cls["attribute_values"]["thick"] < 0.5
    with pytest.raises(ServiceError, match="422.*closest"):
        robot.interpret("a present for my aunt")
    with pytest.raises(ValueError, match="description, samples or trials"):
        robot.register_class("nothing")


def test_a_class_is_enrolled_from_its_touches(best_service, best_base):
    """register_class(samples=...) sends the touches as POST /v1/classes takes them; the
    class is learnt from them and keeps them as sent; add_sample adds one more."""
    client, _, worker = best_service
    _, dataset = best_base
    robot = TactileClient(http=client, retries=0)
    rng = np.random.default_rng(0)
    touches = dataset.samples[dataset.labels == 2][:4]
    touches = touches + rng.normal(0, 0.05, touches.shape).astype(np.float32)
    job = robot.register_class("mug", samples=touches[:3])["job"]  # a batch (N, *input shape)
    assert job["kind"] == "register_class" and job["status"] == "queued"
    worker.run_once()
    assert robot.job(job["id"], wait=2)["status"] == "succeeded"
    cls = client.get(f"/v1/classes/{job['class_id']}").json()
    assert cls["name"] == "mug" and cls["n_samples"] == 3 and cls["in_active_model"]
    stored = client.get(f"/v1/classes/{job['class_id']}/samples").json()["samples"]
    for row, sent in zip(stored, touches[:3], strict=True):
        np.testing.assert_array_equal(robot.sample(job["class_id"], row["id"]), sent)
    added = robot.add_sample(job["class_id"], touches[3])
    assert added["recognized_as"]["class_name"] and added["job"]["status"] == "queued"
    # a list of samples and a description together, as the API takes them
    worded = robot.register_class(
        "mug two", samples=[t.tolist() for t in touches[:2]], description="a smooth hard mug"
    )["job"]
    worker.run_once()
    assert robot.job(worded["id"])["status"] == "succeeded"
    assert client.get(f"/v1/classes/{worded['class_id']}").json()["n_samples"] == 2


def test_touches_the_service_refuses_are_errors_and_nothing_is_stored(best_service, best_base):
    client, _, _ = best_service
    _, dataset = best_base
    robot = TactileClient(http=client, retries=0)
    before = client.get("/v1/classes").json()["classes"]
    partial = dataset.samples[:2].copy()
    partial[1, 0, 0] = np.nan  # sent as null, which enrolment refuses with a 422
    with pytest.raises(ServiceError) as refused:
        robot.register_class("cup", samples=partial)
    assert refused.value.status == 422 and "samples[1]" in str(refused.value)
    with pytest.raises(ServiceError) as refused:  # this model takes samples, not trials
        robot.register_class("cup", trials=[{"fingers": [{"pdc": [0.0]}]}])
    assert refused.value.status in (409, 422)
    assert client.get("/v1/classes").json()["classes"] == before
    with pytest.raises(ValueError, match="samples or trials, not both"):
        robot.register_class("cup", samples=dataset.samples[:1], trials=[{}])
    with pytest.raises(ValueError, match="exactly one of sample or trial"):
        robot.add_sample(1)


def test_a_broken_sensor_abstains_online_and_offline(robot, dataset, tmp_path):
    """Zeros, a saturated sensor and a dead channel: no class named, online or from the
    model file; ``outliers="answer"`` gives the model's guess, flagged, in both."""
    robot.sync_model()
    sound = dataset.samples[0]
    dead = sound.copy()
    dead[live_channel(dataset)] = 0.0  # a channel that reads well away from 0 goes dead
    x = np.stack([sound, np.zeros_like(sound), np.full_like(sound, 1e6), dead])
    away = unreachable(tmp_path, retries=0)
    for answer in (robot.recognize(x), away.recognize(x)):
        kinds = [r["kind"] for r in answer["results"]]
        assert kinds[0] in ("known", "novel") and kinds[1:] == ["input_outlier"] * 3
        assert [r["class_name"] for r in answer["results"][1:]] == [None] * 3
        assert [r["is_novel"] for r in answer["results"][1:]] == [None] * 3
    online = robot.recognize(x, outliers="answer")
    offline = away.recognize(x, outliers="answer")
    for answer in (online, offline):
        assert all(r["class_name"] and r["kind"] != "input_outlier" for r in answer["results"])
        assert [r["input_outlier"] for r in answer["results"]] == [False, True, True, True]
    assert [r["class_name"] for r in online["results"]] == [
        r["class_name"] for r in offline["results"]
    ]
    with pytest.raises(ValueError, match="outliers must be one of"):
        robot.recognize(x, outliers="guess")
