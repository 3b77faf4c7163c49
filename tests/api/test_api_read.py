"""Read endpoints, health, metrics and the offline docs page."""

from __future__ import annotations

import io
import re

import numpy as np
from sqlalchemy import func, select

from app.store.models import Bundle
from app.testing.service import unused_vectors

PROBLEM = "application/problem+json"


def test_attributes_in_vector_order(client, dataset):
    r = client.get("/v1/attributes")
    assert r.status_code == 200
    assert r.json()["attributes"] == list(dataset.attribute_names)
    vocabulary = r.json()["vocabulary"]
    assert [a["name"] for a in vocabulary] == list(dataset.attribute_names)
    assert {a["origin"] for a in vocabulary} == {"dataset"}
    assert all(a["retired_at"] is None for a in vocabulary)


def test_classes_list_the_base_model(client, dataset):
    classes = client.get("/v1/classes").json()["classes"]
    assert [c["name"] for c in classes] == list(dataset.class_names)
    first = classes[0]
    assert first["kind"] == "known" and first["in_active_model"] is True
    assert first["n_samples"] == int((dataset.labels == 0).sum())
    expected = [
        a
        for a, bit in zip(dataset.attribute_names, dataset.class_attributes[0], strict=True)
        if bit
    ]
    assert first["attributes"] == expected
    assert first["created_at"].endswith("Z") or "+00:00" in first["created_at"]


def test_get_class_by_id(client):
    listed = client.get("/v1/classes").json()["classes"][3]
    assert client.get(f"/v1/classes/{listed['id']}").json() == listed


def test_unknown_class_id_is_a_named_404(client):
    r = client.get("/v1/classes/999999")
    assert r.status_code == 404
    assert r.headers["content-type"] == PROBLEM
    body = r.json()
    assert body["status"] == 404 and body["instance"] == "/v1/classes/999999"
    assert body["errors"][0]["field"] == "class_id"


def test_non_integer_ids_are_named_422(client):
    for path, field in (
        ("/v1/classes/abc", "class_id"),
        ("/v1/jobs/x", "job_id"),
        ("/v1/models/v1/activate", "version"),
        ("/v1/classes/0", "class_id"),
        ("/v1/jobs/99999999999999999999999", "job_id"),
        ("/v1/classes/-3", "class_id"),
    ):
        r = client.request("POST" if path.endswith("activate") else "GET", path)
        assert r.status_code == 422, path
        assert r.headers["content-type"] == PROBLEM
        assert r.json()["errors"][0]["field"] == field


def test_unknown_job_id_is_a_named_404(client):
    r = client.get("/v1/jobs/424242")
    assert r.status_code == 404 and r.headers["content-type"] == PROBLEM
    assert r.json()["errors"] == [{"field": "job_id", "reason": "no job with job_id 424242"}]


def test_models_and_active_model(client, dataset):
    models = client.get("/v1/models").json()["models"]
    assert len(models) == 1
    summary = models[0]
    assert (
        summary["version"] == 1 and summary["active"] is True and summary["reason"] == "bootstrap"
    )
    assert summary["input_shape"] == list(dataset.input_shape)
    assert summary["class_count"] == dataset.n_classes and "classes" not in summary
    assert len(summary["sha256"]) == 64 and isinstance(summary["metrics"], dict)
    v1 = client.get("/v1/models/1").json()
    assert {c["name"] for c in v1["classes"]} == set(dataset.class_names)
    assert {k: v for k, v in v1.items() if k != "classes"} == summary
    assert client.get("/v1/models/active").json() == v1


def test_unknown_model_version_is_a_named_404(client):
    r = client.get("/v1/models/77")
    assert r.status_code == 404 and r.headers["content-type"] == PROBLEM
    assert r.json()["errors"] == [
        {"field": "version", "reason": "no model version with version 77"}
    ]


def test_health_and_readiness(client):
    batch_limit = client.app.state.service.settings.batch_limit  # a client splits by it
    assert client.get("/healthz").json() == {
        "status": "ok",
        "model_version": 1,
        "batch_limit": batch_limit,
    }
    assert client.get("/readyz").json() == {"status": "ready", "model_version": 1}


def test_metrics_are_prometheus_text(client, app, sample):
    client.post("/v1/recognize", json={"samples": [sample]})
    r = client.get("/metrics")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/plain")
    text = r.text
    assert (
        'tactile_http_requests_total{method="POST",route="/v1/recognize",status="200"} 1.0' in text
    )
    assert "tactile_http_request_duration_seconds_bucket" in text
    assert "tactile_recognitions_total" in text
    assert "tactile_active_model_version 1.0" in text
    assert 'tactile_jobs{status="queued"} 0.0' in text
    assert "tactile_model_versions_stored 1.0" in text
    stored = float(re.search(r"^tactile_model_bundle_bytes (\S+)$", text, re.M).group(1))
    with app.state.service.sessions() as s:
        assert stored == s.scalar(select(func.sum(Bundle.size))) > 0


def test_docs_page_needs_no_internet(client):
    html = client.get("/docs").text
    assert "/static/swagger-ui/swagger-ui-bundle.js" in html
    assert "cdn" not in html.lower() and "https://" not in html
    assert client.get("/static/swagger-ui/swagger-ui-bundle.js").status_code == 200
    assert client.get("/static/swagger-ui/swagger-ui.css").status_code == 200


def test_openapi_documents_problem_responses_and_npy(client):
    spec = client.get("/openapi.json").json()
    recognize = spec["paths"]["/v1/recognize"]["post"]
    assert set(recognize["requestBody"]["content"]) == {
        "application/json",
        "application/x-npy",
        "application/x-hdf5",
    }
    assert PROBLEM in recognize["responses"]["422"]["content"]
    register = spec["paths"]["/v1/classes"]["post"]
    assert "202" in register["responses"] and "409" in register["responses"]


def test_operation_ids_name_the_operation_for_client_generators(client):
    spec = client.get("/openapi.json").json()
    ids = [op["operationId"] for item in spec["paths"].values() for op in item.values()]
    assert len(ids) == len(set(ids))
    assert spec["paths"]["/v1/classes"]["post"]["operationId"] == "classes-register_class"
    assert (
        spec["paths"]["/v1/classes/{class_id}/samples"]["post"]["operationId"]
        == "samples-add_sample"
    )
    assert spec["paths"]["/v1/recognize"]["post"]["operationId"] == "recognize-recognize"
    assert not [i for i in ids if "_v1_" in i]  # no path-and-method names left


def test_unknown_route_and_method_are_problems(client):
    r = client.get("/v1/nothing-here")
    assert r.status_code == 404 and r.headers["content-type"] == PROBLEM
    r = client.delete("/v1/classes")
    assert r.status_code == 405 and r.headers["content-type"] == PROBLEM


def test_readiness_fails_without_a_store_or_a_model(client, app, monkeypatch):
    from sqlalchemy import create_engine

    from app.store.db import make_sessionmaker

    working = app.state.service.sessions
    app.state.service.sessions = make_sessionmaker(
        create_engine("sqlite:////nonexistent-dir/tactile.db")
    )
    try:
        r = client.get("/readyz")
        assert r.status_code == 503 and r.json()["errors"][0]["field"] == "database"
        assert client.get("/healthz").status_code == 200  # alive all the same
        assert client.get("/metrics").status_code == 200  # process metrics still served
    finally:
        app.state.service.sessions = working
    monkeypatch.setattr(app.state.service.holder, "_current", None)
    r = client.get("/readyz")
    assert r.status_code == 503 and r.headers["retry-after"] == "5"
    r = client.post("/v1/recognize", json={"samples": [[0.0]]})
    assert r.status_code == 503 and r.json()["errors"][0]["field"] == "model"


def test_every_request_gives_its_database_connection_back(client, app):
    """Sessions are opened and closed on the event loop (closing goes to a worker thread
    where giving a connection back is a network round trip): none may stay checked out,
    after answers and after errors alike."""
    pool = app.state.service.sessions.kw["bind"].pool
    app.state.service.holder.stop()  # its poll for new model versions checks a connection out too
    for _ in range(5):
        assert client.get("/v1/classes").status_code == 200
        assert client.get("/v1/jobs/999999").status_code == 404
        assert (
            client.post("/v1/classes", json={"name": "", "attributes": ["nope"]}).status_code == 422
        )
    assert pool.checkedout() == 0


def test_classes_come_a_page_at_a_time(client, dataset):
    everything = client.get("/v1/classes", params={"limit": 1000}).json()
    assert everything["next_after"] is None and len(everything["classes"]) == dataset.n_classes
    pages, params = [], {"limit": 7}
    while True:
        body = client.get("/v1/classes", params=params).json()
        assert len(body["classes"]) <= 7
        pages.append(body["classes"])
        if body["next_after"] is None:
            break
        assert body["next_after"] == body["classes"][-1]["id"]
        params = {"limit": 7, "after": body["next_after"]}
    assert len(pages) == -(-dataset.n_classes // 7)
    assert [c for page in pages for c in page] == everything["classes"]
    last = everything["classes"][-1]["id"]
    assert client.get("/v1/classes", params={"after": last}).json() == {
        "classes": [],
        "next_after": None,
    }


def test_models_come_a_page_at_a_time(client):
    body = client.get("/v1/models", params={"limit": 1}).json()
    assert [m["version"] for m in body["models"]] == [1] and body["next_after"] is None
    assert client.get("/v1/models", params={"after": 1}).json() == {
        "models": [],
        "next_after": None,
    }


def test_bad_page_parameters_are_named_422(client):
    for path in ("/v1/classes", "/v1/models"):
        for params, field in (
            ({"limit": 0}, "limit"),
            ({"limit": 1001}, "limit"),
            ({"after": -1}, "after"),
            ({"after": "x"}, "after"),
        ):
            r = client.get(path, params=params)
            assert r.status_code == 422 and r.headers["content-type"] == PROBLEM, (path, params)
            assert r.json()["errors"][0]["field"] == field


def test_a_dataset_class_lists_its_training_trials_a_page_at_a_time(client, dataset):
    trials = sorted(int(t) for t in dataset.trials[dataset.labels == 0])
    first = client.get("/v1/classes/1/samples", params={"limit": 3}).json()
    assert len(first["samples"]) == 3 and first["next_after"] == first["samples"][-1]["id"]
    rest = client.get("/v1/classes/1/samples", params={"after": first["next_after"]}).json()
    samples = first["samples"] + rest["samples"]
    assert rest["next_after"] is None and len(samples) == len(trials)
    assert sorted(s["trial"] for s in samples) == trials
    assert {(s["origin"], s["enrolled_by"]) for s in samples} == {("dataset", None)}
    assert "data" not in samples[0] and "sample" not in samples[0]


def test_an_enrolled_class_lists_its_live_samples_and_who_added_them(client, dataset, sample):
    r = client.post(
        "/v1/classes", json={"name": "mug", "attribute_vector": unused_vectors(dataset, 1)[0]}
    )
    cid = r.json()["class"]["id"]
    ids = [
        client.post(f"/v1/classes/{cid}/samples", json={"sample": sample}).json()["sample_id"]
        for _ in range(3)
    ]
    assert client.delete(f"/v1/classes/{cid}/samples/{ids[1]}").status_code == 202
    samples = client.get(f"/v1/classes/{cid}/samples").json()["samples"]
    assert [s["id"] for s in samples] == [ids[0], ids[2]]  # the withdrawn one is gone
    assert all(s["origin"] == "enrolled" and s["trial"] is None for s in samples)
    assert {s["enrolled_by"] for s in samples} == {"addr:testclient"}
    r = client.get("/v1/classes/424242/samples")
    assert r.status_code == 404 and r.json()["errors"][0]["field"] == "class_id"


def test_one_sample_comes_back_with_its_data_as_json_or_npy(client, dataset, sample):
    cid = client.post(
        "/v1/classes", json={"name": "mug", "attribute_vector": unused_vectors(dataset, 1)[0]}
    ).json()["class"]["id"]
    sid = client.post(f"/v1/classes/{cid}/samples", json={"sample": sample}).json()["sample_id"]
    got = client.get(f"/v1/classes/{cid}/samples/{sid}").json()
    assert {k: got[k] for k in ("id", "origin", "trial", "enrolled_by")} == {
        "id": sid,
        "origin": "enrolled",
        "trial": None,
        "enrolled_by": "addr:testclient",
    }
    assert got["shape"] == list(dataset.samples.shape[1:])
    np.testing.assert_array_equal(
        np.float32(got["sample"]), np.float32(sample)
    )  # exactly what was sent

    r = client.get(f"/v1/classes/{cid}/samples/{sid}", headers={"Accept": "application/x-npy"})
    assert r.status_code == 200 and r.headers["content-type"] == "application/x-npy"
    x = np.load(io.BytesIO(r.content), allow_pickle=False)
    np.testing.assert_array_equal(x, np.float32(sample))
    again = client.post(
        "/v1/recognize", content=r.content, headers={"Content-Type": "application/x-npy"}
    )
    assert again.status_code == 200 and len(again.json()["results"]) == 1  # sent back as it came

    first = client.get("/v1/classes/1/samples", params={"limit": 1}).json()["samples"][0]
    trial = client.get(f"/v1/classes/1/samples/{first['id']}").json()
    assert trial["origin"] == "dataset" and trial["trial"] == first["trial"]
    np.testing.assert_array_equal(
        np.float32(trial["sample"]), dataset.samples[dataset.trials == trial["trial"]][0]
    )


def test_a_sample_that_is_not_there_is_a_named_404(client, dataset, sample):
    cid = client.post(
        "/v1/classes", json={"name": "mug", "attribute_vector": unused_vectors(dataset, 1)[0]}
    ).json()["class"]["id"]
    sid = client.post(f"/v1/classes/{cid}/samples", json={"sample": sample}).json()["sample_id"]
    for path, field in (
        (f"/v1/classes/424242/samples/{sid}", "class_id"),
        (f"/v1/classes/1/samples/{sid}", "sample_id"),  # another class's
        (f"/v1/classes/{cid}/samples/424242", "sample_id"),
    ):
        r = client.get(path)
        assert r.status_code == 404 and r.headers["content-type"] == PROBLEM, path
        assert r.json()["errors"][0]["field"] == field, path
    assert client.delete(f"/v1/classes/{cid}/samples/{sid}").status_code == 202
    r = client.get(f"/v1/classes/{cid}/samples/{sid}")  # withdrawn: no longer live
    assert r.status_code == 404 and r.json()["errors"][0]["field"] == "sample_id"
