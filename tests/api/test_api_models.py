"""Model versions: activation (rollback), and the holder swapping without a restart."""

from __future__ import annotations

from tests.service_fixtures import unused_vectors

PROBLEM = "application/problem+json"


def enroll_and_retrain(client, worker, dataset) -> int:
    vector = unused_vectors(dataset, 1)[0]
    r = client.post("/v1/classes", json={"name": "cup", "attribute_vector": vector})
    assert worker.run_once() == 1
    job = client.get(f"/v1/jobs/{r.json()['job']['id']}").json()
    assert job["status"] == "succeeded"
    return r.json()["class"]["id"]


def test_rollback_and_forward_again(client, worker, dataset, sample):
    cid = enroll_and_retrain(client, worker, dataset)
    assert client.get("/v1/models/active").json()["version"] == 2
    assert client.post("/v1/recognize", json={"samples": [sample]}).json()["model_version"] == 2

    r = client.post("/v1/models/1/activate")
    assert r.status_code == 200 and r.json()["version"] == 1 and r.json()["active"] is True
    assert client.post("/v1/recognize", json={"samples": [sample]}).json()["model_version"] == 1
    assert client.get(f"/v1/classes/{cid}").json()["in_active_model"] is False
    assert [m["active"] for m in client.get("/v1/models").json()["models"]] == [True, False]

    assert client.post("/v1/models/2/activate").json()["version"] == 2
    assert client.get(f"/v1/classes/{cid}").json()["in_active_model"] is True


def test_each_version_lists_its_own_class_count(client, worker, dataset):
    enroll_and_retrain(client, worker, dataset)
    summaries = client.get("/v1/models").json()["models"]
    assert [m["class_count"] for m in summaries] == [dataset.n_classes, dataset.n_classes + 1]
    v2 = client.get("/v1/models/2").json()
    assert v2["class_count"] == len(v2["classes"]) and {"name": "cup", "kind": "novel"} in v2["classes"]


def test_activate_unknown_version_is_404(client):
    r = client.post("/v1/models/99/activate")
    assert r.status_code == 404 and r.headers["content-type"] == PROBLEM
    assert r.json()["errors"][0]["field"] == "version"


def test_activate_a_corrupt_bundle_is_409_and_changes_nothing(client, app, worker, dataset):
    from sqlalchemy import update

    from app.store.models import Bundle, ModelVersion

    enroll_and_retrain(client, worker, dataset)
    client.post("/v1/models/1/activate")
    with app.state.sessions.begin() as s:
        sha = s.get(ModelVersion, 2).bundle_sha256
        s.execute(update(Bundle).where(Bundle.sha256 == sha).values(data=b"garbage"))
    r = client.post("/v1/models/2/activate")
    assert r.status_code == 409 and r.json()["errors"][0]["field"] == "version"
    assert client.get("/v1/models/active").json()["version"] == 1


def test_other_processes_pick_up_a_new_version_by_polling(client, app, worker, dataset, sample):
    """The holder polls the active version: a change made by anyone shows up without restart."""
    import time

    worker.on_activate = None  # as if the worker ran in another process
    enroll_and_retrain(client, worker, dataset)
    deadline = time.monotonic() + 10
    while app.state.holder.current.version != 2 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert client.post("/v1/recognize", json={"samples": [sample]}).json()["model_version"] == 2


def test_a_model_handed_over_by_an_embedded_worker_is_served_only_while_active(
    client, app, worker, dataset, sample
):
    """The embedded worker hands its new model to the holder (no reload from the store);
    a version that was rolled back meanwhile is not served: the active one is."""
    holder = app.state.holder
    enroll_and_retrain(client, worker, dataset)
    built = holder.current.recognizer
    assert client.post("/v1/recognize", json={"samples": [sample]}).json()["model_version"] == 2

    client.post("/v1/models/1/activate")
    assert holder.serve(2, built) is False  # it serves the active version 1 already
    assert holder.current.version == 1 and holder.current.recognizer is not built
    assert client.post("/v1/recognize", json={"samples": [sample]}).json()["model_version"] == 1

    client.post("/v1/models/2/activate")
    assert holder.serve(2, built) is True and holder.current.recognizer is built
