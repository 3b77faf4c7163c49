"""POST /v1/recognize: JSON and .npy bodies, and every way a batch can be wrong."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.api.schemas import RecognizeResponse
from tests.service_fixtures import PROBLEM, npy, problem

NPY = {"content-type": "application/x-npy"}


def test_json_batch(client, dataset):
    r = client.post("/v1/recognize", json={"samples": dataset.samples[:3].tolist()})
    assert r.status_code == 200
    body = r.json()
    assert body["model_version"] == 1 and len(body["results"]) == 3
    names = set(dataset.class_names)
    for res in body["results"]:
        assert res["class_name"] in names and res["kind"] in ("known", "novel")
        assert isinstance(res["class_id"], int) and isinstance(res["is_novel"], bool)
        assert len(res["top_k"]) == 3
        probs = [s["probability"] for s in res["top_k"]]
        assert probs == sorted(probs, reverse=True)
        assert res["top_k"][0]["class_name"] == res["class_name"]
    RecognizeResponse.model_validate(body)  # the documented schema, field for field


def test_fast_json_path_agrees_with_the_validating_one(client, dataset):
    """Well-formed numbers take the orjson fast path; a body it does not take (here a
    numeric string, which the schema coerces) goes through pydantic: same answers."""
    x = dataset.samples[:2].astype(np.float64)
    fast = client.post("/v1/recognize", json={"samples": x.tolist()}).json()
    as_ints = client.post("/v1/recognize", json={"samples": np.rint(x * 0).astype(int).tolist()})
    assert as_ints.status_code == 200
    slow_body = x.tolist()
    slow_body[0][0][0] = str(slow_body[0][0][0])
    slow = client.post("/v1/recognize", json={"samples": slow_body}).json()
    assert slow == fast


def test_npy_batch_matches_json(client, dataset):
    x = dataset.samples[:4]
    by_json = client.post("/v1/recognize", json={"samples": x.tolist()}).json()
    by_npy = client.post("/v1/recognize", content=npy(x), headers=NPY).json()
    assert [r["class_name"] for r in by_npy["results"]] == [
        r["class_name"] for r in by_json["results"]
    ]


def test_npy_single_sample_without_batch_axis(client, dataset):
    r = client.post("/v1/recognize", content=npy(dataset.samples[0]), headers=NPY)
    assert r.status_code == 200 and len(r.json()["results"]) == 1


def test_npy_float64_and_int_are_accepted(client, dataset):
    r = client.post(
        "/v1/recognize", content=npy(dataset.samples[:2].astype(np.float64)), headers=NPY
    )
    assert r.status_code == 200
    r = client.post(
        "/v1/recognize", content=npy(np.ones((1, *dataset.input_shape), np.int32)), headers=NPY
    )
    assert r.status_code == 200


def test_wrong_sample_shape(client, dataset):
    c, t = dataset.input_shape
    body = problem(
        client.post("/v1/recognize", json={"samples": [np.zeros((c, t + 1)).tolist()]}),
        422,
        "samples[0]",
    )
    assert str(t + 1) in body["detail"]
    problem(
        client.post("/v1/recognize", content=npy(np.zeros((2, c + 1, t), np.float32)), headers=NPY),
        422,
        "samples",
    )


def test_ragged_sample(client, sample):
    shape = list(np.shape(sample))
    sample[1] = sample[1][:-1]
    body = problem(
        client.post("/v1/recognize", json={"samples": [sample, sample]}), 422, "samples[0]"
    )
    assert "rows have different lengths" in body["detail"] and str(shape) in body["detail"]


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_values_by_npy(client, dataset, bad):
    x = dataset.samples[:3].copy()
    x[2, 1, 1] = bad
    body = problem(client.post("/v1/recognize", content=npy(x), headers=NPY), 422, "samples")
    # NaN is a missing procedure, and one value of it missing is named as such
    why = "infinity" if np.isinf(bad) else "procedure 'squeeze' is partly missing"
    assert why in body["detail"] and "sample 2" in body["detail"]


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity"])
def test_non_finite_values_by_json_literal(client, sample, literal):
    sample[0][0] = "__BAD__"
    raw = json.dumps({"samples": [sample]}).replace('"__BAD__"', literal)
    r = client.post("/v1/recognize", content=raw, headers={"content-type": "application/json"})
    why = "infinity" if "Infinity" in literal else "procedure 'squeeze' is partly missing"
    assert why in problem(r, 422, "samples")["detail"]


def test_empty_batch(client, dataset):
    problem(client.post("/v1/recognize", json={"samples": []}), 422, "samples")
    empty = np.zeros((0, *dataset.input_shape), np.float32)
    problem(client.post("/v1/recognize", content=npy(empty), headers=NPY), 422, "samples")


def test_oversized_batch(client, app, dataset):
    app.state.service.recognition.batch_limit = 2
    x = dataset.samples[:3]
    body = problem(client.post("/v1/recognize", json={"samples": x.tolist()}), 422, "samples")
    assert "batch limit of 2" in body["detail"]
    assert "send at most 2 a request, or raise TACTILE_BATCH_LIMIT" in body["detail"]
    problem(client.post("/v1/recognize", content=npy(x), headers=NPY), 422, "samples")
    assert client.post("/v1/recognize", json={"samples": x[:2].tolist()}).status_code == 200


def test_body_over_the_size_cap_is_413(tmp_path, base_model):
    from fastapi.testclient import TestClient

    from app.api.main import create_app
    from app.testing.service import quick_settings

    settings = quick_settings(tmp_path / "d", max_body_bytes=1024)
    with TestClient(create_app(settings, trainer=lambda: base_model)) as c:
        body = npy(base_model[1].samples[:2])
        r = c.post("/v1/recognize", content=body, headers=NPY)
        assert r.status_code == 413 and r.headers["content-type"] == PROBLEM
        assert r.json()["errors"][0]["field"] == "body"
        r = c.post("/v1/recognize", content=iter([body[:900], body[900:]]), headers=NPY)  # chunked
        assert r.status_code == 413 and r.headers["content-type"] == PROBLEM


def test_malformed_json(client):
    for raw in (b"{", b"", b"[1, 2", b"\xff\xfe", b"[" * 100_000):
        r = client.post("/v1/recognize", content=raw, headers={"content-type": "application/json"})
        body = problem(r, 422, "body")
        assert "JSON" in body["detail"] or "body" in body["detail"]


def test_wrong_json_shapes_name_the_field(client, sample):
    problem(client.post("/v1/recognize", json={"sample": [sample]}), 422, "samples")  # missing
    problem(client.post("/v1/recognize", json={"samples": [sample], "extra": 1}), 422, "extra")
    problem(client.post("/v1/recognize", json={"samples": "abc"}), 422, "samples")
    r = client.post("/v1/recognize", json={"samples": [[["x"] * 3]]})
    assert r.status_code == 422 and r.json()["errors"][0]["field"].startswith("samples[0]")
    problem(client.post("/v1/recognize", json=[1, 2]), 422, "body")


def test_bad_npy_bodies(client, dataset):
    problem(client.post("/v1/recognize", content=b"not an npy file", headers=NPY), 422, "body")
    problem(
        client.post("/v1/recognize", content=npy(dataset.samples[:1])[:-10], headers=NPY),
        422,
        "body",
    )
    strings = npy(np.array([["a"] * dataset.input_shape[1]] * dataset.input_shape[0]))
    problem(client.post("/v1/recognize", content=strings, headers=NPY), 422, "body")
    obj = npy(np.array([{"a": 1}], dtype=object))  # pickled: never loaded
    problem(client.post("/v1/recognize", content=obj, headers=NPY), 422, "body")


def test_touches_of_one_object_get_one_fused_answer(client, dataset):
    x = dataset.samples[dataset.labels == 2][:3].tolist()
    each = client.post("/v1/recognize", json={"samples": x}).json()["results"]
    one = client.post("/v1/recognize?same_object=1", json={"samples": x}).json()["results"]
    assert len(each) == 3 and len(one) == 1
    scores = [r["novelty_score"] for r in each]
    assert np.isclose(one[0]["novelty_score"], np.mean(scores))  # the mean of their evidence
    single = client.post("/v1/recognize?same_object=true", json={"samples": x[:1]}).json()
    (alone,) = single["results"]  # a group of one is that sample's answer
    assert alone["class_name"] == each[0]["class_name"]
    assert np.isclose(alone["novelty_score"], each[0]["novelty_score"])  # torch: batch-size bits
    bad = problem(client.post("/v1/recognize?same_object=maybe", json={"samples": x}), 422)
    assert bad["detail"] == "same_object: not true or false (got 'maybe')"
    assert bad["errors"] == [{"field": "same_object", "reason": "not true or false (got 'maybe')"}]
    spec = client.get("/openapi.json").json()["paths"]["/v1/recognize"]["post"]
    assert [p["name"] for p in spec["parameters"]] == [
        "same_object",
        "target_confidence",
        "known_kept",
        "outliers",
        "min_model_version",
        "objects",
        "X-Tactile-Objects",
    ]


def test_min_model_version_answers_with_the_enrolment_a_job_waited_for(
    settings, base_model, dataset
):
    """An API process learns of a version made elsewhere (another process's worker) at its
    next poll; ``min_model_version`` makes it load that version first, so that a robot that
    waited for its enrolment's job is answered by a model holding it, whichever process
    answers. An older active version is a 409, a bad value a 422."""
    from fastapi.testclient import TestClient

    from app.api.main import create_app
    from app.client import ServiceError, TactileClient
    from app.store import repo
    from app.testing.service import unused_vectors
    from worker import Worker

    slow = settings.model_copy(update={"model_poll_seconds": 3600})  # no poll in this test
    app = create_app(slow, trainer=lambda: base_model)
    with TestClient(app) as client:
        sessions = app.state.service.sessions
        elsewhere = Worker(slow, sessions)  # not this process's: it does not hand its model over
        vector = unused_vectors(dataset, 1)[0]
        created = client.post(
            "/v1/classes", json={"name": "cup", "attribute_vector": vector}
        ).json()
        assert elsewhere.run_once() == 1
        with sessions() as s:
            made = repo.get_job(s, created["job"]["id"]).model_version
            assert repo.active_version_number(s) == made == 2
        x = npy(dataset.samples[:2])
        assert client.post("/v1/recognize", content=x, headers=NPY).json()["model_version"] == 1

        r = client.post("/v1/recognize?min_model_version=2", content=x, headers=NPY)
        assert r.status_code == 200 and r.json()["model_version"] == 2
        assert app.state.service.holder.current.class_ids["cup"] == created["class"]["id"]
        assert client.get("/healthz").json()["model_version"] == 2  # served from now on
        robot = TactileClient(http=client, retries=0, timeout=2)
        assert robot.recognize(dataset.samples[:1], min_model_version=2)["model_version"] == 2
        assert robot.recognize(dataset.samples[:1], min_model_version=1)["model_version"] == 2

        r = client.post("/v1/recognize?min_model_version=3", content=x, headers=NPY)
        body = problem(r, 409, "min_model_version")
        assert "model version 3 is not active" in body["detail"]
        assert "the active version is 2" in body["detail"]
        with pytest.raises(ServiceError):
            robot.recognize(dataset.samples[:1], min_model_version=3)
        for bad in ("0", "-1", "1.5", "two", ""):
            r = client.post(f"/v1/recognize?min_model_version={bad}", content=x, headers=NPY)
            assert "min_model_version" in problem(r, 422, "min_model_version")["detail"]


def test_waiting_for_a_version_shares_one_load_and_holds_no_request_thread(
    settings, base_model, dataset
):
    """A fleet that asks for a new version at once, more requests than the request thread
    pool has slots: they share one load, recognition without ``min_model_version`` is
    answered meanwhile, and past ``model_wait_seconds`` each gets a 503 with Retry-After
    while the load goes on to serve the version."""
    import threading
    import time

    import anyio.to_thread
    from fastapi.testclient import TestClient

    from app.api.main import create_app
    from app.testing.service import unused_vectors
    from worker import Worker

    slots, fleet = 4, 12
    slow = settings.model_copy(update={"model_poll_seconds": 3600, "model_wait_seconds": 1.0})
    app = create_app(slow, trainer=lambda: base_model)
    with TestClient(app) as client:
        client.portal.call(
            lambda: setattr(anyio.to_thread.current_default_thread_limiter(), "total_tokens", slots)
        )
        holder = app.state.service.holder
        vector = unused_vectors(dataset, 1)[0]
        created = client.post("/v1/classes", json={"name": "cup", "attribute_vector": vector})
        assert Worker(slow, app.state.service.sessions).run_once() == 1  # another process's
        x = npy(dataset.samples[:2])
        answers: list = [None] * fleet

        def ask(i: int) -> None:
            answers[i] = client.post("/v1/recognize?min_model_version=2", content=x, headers=NPY)

        # this process's worker is handing a version over: a refresh waits for it (up to a
        # minute), as a load of a large model takes seconds
        with holder.handing_over():
            robots = [threading.Thread(target=ask, args=(i,)) for i in range(fleet)]
            for t in robots:
                t.start()
            time.sleep(0.3)  # all of them waiting now
            loads = [t for t in threading.enumerate() if t.name == "model-load"]
            assert len(loads) == 1
            started = time.monotonic()
            plain = client.post("/v1/recognize", content=x, headers=NPY)
            assert plain.status_code == 200 and plain.json()["model_version"] == 1
            assert time.monotonic() - started < 5  # not queued behind them (a minute before)
            # the job is answered at once: its answer does not wait for the load
            job = client.get(f"/v1/jobs/{created.json()['job']['id']}")
            assert job.status_code == 200 and job.json()["model_version"] == 2
            for t in robots:
                t.join(timeout=30)
            assert holder.current.version == 1
        for r in answers:
            body = problem(r, 503, "min_model_version")
            assert r.headers["retry-after"] == "5"
            assert "TACTILE_MODEL_WAIT_SECONDS" in body["detail"]
        loads[0].join(timeout=30)  # the load went on once the handover ended
        assert holder.current.version == 2
        r = client.post("/v1/recognize?min_model_version=2", content=x, headers=NPY)
        assert r.status_code == 200 and r.json()["model_version"] == 2
        assert client.get(f"/v1/jobs/{created.json()['job']['id']}").status_code == 200


def test_known_kept_moves_the_operating_point_of_one_answer(client, app, dataset):
    """A request's ``known_kept`` routes its answers by the threshold that kept that share
    of held-out known touches: a lower share calls more samples novel; the answer without
    it keeps 0.90, the service's default; a share outside (0, 1) is a 422 naming the
    parameter."""
    x = dataset.samples[:64]
    rec = app.state.service.holder.current.recognizer
    low_t, high_t = rec.threshold_keeping(0.05), rec.threshold_keeping(0.99)
    assert low_t < high_t

    def novel(**params) -> int:
        r = client.post("/v1/recognize", content=npy(x), headers=NPY, params=params)
        assert r.status_code == 200, r.text
        return sum(res["is_novel"] for res in r.json()["results"])

    scores = rec.novelty_score(x)
    assert novel(known_kept=0.05) == int((scores > low_t).sum())
    assert novel(known_kept=0.99) == int((scores > high_t).sum())
    assert novel() == int((scores > rec.threshold_keeping(0.90)).sum())
    assert novel(known_kept=0.05) > novel(known_kept=0.99)
    one = client.post("/v1/recognize", content=npy(x[0]), headers=NPY, params={"known_kept": 0.05})
    assert one.json()["results"][0]["is_novel"] == bool(scores[0] > low_t)  # through the batcher
    for bad in ("0", "1", "1.5", "much"):
        r = client.post(
            "/v1/recognize", content=npy(x[:1]), headers=NPY, params={"known_kept": bad}
        )
        assert "a share in (0, 1)" in problem(r, 422, "known_kept")["detail"], r.text


def test_the_service_wide_known_kept_is_each_answers_default(tmp_path, base_model):
    from fastapi.testclient import TestClient

    from app.api.main import create_app
    from app.testing.service import quick_settings

    settings = quick_settings(tmp_path / "data").model_copy(update={"known_kept": 0.05})
    with TestClient(create_app(settings, trainer=lambda: base_model)) as c:
        rec = c.app.state.service.holder.current.recognizer
        x = base_model[1].samples[:32]
        scores = rec.novelty_score(x)
        body = c.post("/v1/recognize", content=npy(x), headers=NPY).json()
        flagged = [res["is_novel"] for res in body["results"]]
        assert flagged == (scores > rec.threshold_keeping(0.05)).tolist()
        own = c.post("/v1/recognize", content=npy(x), headers=NPY, params={"known_kept": 0.99})
        assert [res["is_novel"] for res in own.json()["results"]] == (
            scores > rec.threshold_keeping(0.99)
        ).tolist()
