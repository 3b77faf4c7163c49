"""Model versions: activation (rollback), and the holder swapping without a restart."""

from __future__ import annotations

from app.testing.service import unused_vectors
from tests.service_fixtures import problem

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
    assert (
        v2["class_count"] == len(v2["classes"])
        and {"name": "cup", "kind": "novel"} in v2["classes"]
    )


def test_activate_unknown_version_is_404(client):
    r = client.post("/v1/models/99/activate")
    assert r.status_code == 404 and r.headers["content-type"] == PROBLEM
    assert r.json()["errors"][0]["field"] == "version"


def test_activate_a_corrupt_bundle_is_409_and_changes_nothing(client, app, worker, dataset):
    from sqlalchemy import update

    from app.store.models import Bundle, ModelVersion

    enroll_and_retrain(client, worker, dataset)
    client.post("/v1/models/1/activate")
    with app.state.service.sessions.begin() as s:
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
    while app.state.service.holder.current.version != 2 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert client.post("/v1/recognize", json={"samples": [sample]}).json()["model_version"] == 2


def test_a_model_handed_over_by_an_embedded_worker_is_served_only_while_active(
    client, app, worker, dataset, sample
):
    """The embedded worker hands its new model to the holder (no reload from the store);
    a version that was rolled back meanwhile is not served: the active one is."""
    holder = app.state.service.holder
    enroll_and_retrain(client, worker, dataset)
    built = holder.current.recognizer
    assert client.post("/v1/recognize", json={"samples": [sample]}).json()["model_version"] == 2

    client.post("/v1/models/1/activate")
    assert holder.serve(2, built) is False  # it serves the active version 1 already
    assert holder.current.version == 1 and holder.current.recognizer is not built
    assert client.post("/v1/recognize", json={"samples": [sample]}).json()["model_version"] == 1

    client.post("/v1/models/2/activate")
    assert holder.serve(2, built) is True and holder.current.recognizer is built


def test_a_downloaded_bundle_recognises_offline_as_the_service_does(client, worker, dataset):
    """What a robot does before it loses the network: download the active version, then
    recognise with it alone (``bundle.from_bytes``, as ``tactile-zsl recognize`` does)."""
    import numpy as np

    from app.framework import bundle

    enroll_and_retrain(client, worker, dataset)  # version 2 knows the novel class "cup"
    r = client.get("/v1/models/2/bundle")
    assert r.status_code == 200 and r.headers["content-type"] == "application/zip"
    assert r.headers["content-disposition"] == 'attachment; filename="tactile-model-v2.bundle"'
    assert r.headers["etag"] == f'"{client.get("/v1/models/2").json()["sha256"]}"'
    offline = bundle.from_bytes(r.content)
    assert "cup" in offline.registry.novel_names

    x = dataset.samples[::7][:12]
    online = client.post("/v1/recognize", json={"samples": x.tolist()}).json()["results"]
    answers = offline.recognize_batch(x, known_kept=offline.operating_point()).records()
    assert [a["class_name"] for a in answers] == [o["class_name"] for o in online]
    assert [a["is_novel"] for a in answers] == [o["is_novel"] for o in online]
    np.testing.assert_allclose(
        [a["novelty_score"] for a in answers], [o["novelty_score"] for o in online], rtol=1e-5
    )
    for a, o in zip(answers, online, strict=True):
        assert [s["class_name"] for s in a["top_k"]] == [s["class_name"] for s in o["top_k"]]
        np.testing.assert_allclose(
            [s["probability"] for s in a["top_k"]],
            [s["probability"] for s in o["top_k"]],
            rtol=1e-5,
            atol=1e-7,
        )


def test_a_robot_holding_the_version_gets_304(client, worker, dataset):
    enroll_and_retrain(client, worker, dataset)
    v1, v2 = (client.get(f"/v1/models/{v}/bundle") for v in (1, 2))
    assert v1.headers["etag"] != v2.headers["etag"] and v1.content != v2.content
    for held in (
        v2.headers["etag"],
        f"W/{v2.headers['etag']}",
        f"{v1.headers['etag']}, {v2.headers['etag']}",
        "*",
    ):
        r = client.get("/v1/models/2/bundle", headers={"If-None-Match": held})
        assert (
            r.status_code == 304 and r.content == b"" and r.headers["etag"] == v2.headers["etag"]
        ), held
    r = client.get("/v1/models/2/bundle", headers={"If-None-Match": v1.headers["etag"]})
    assert r.status_code == 200 and r.content == v2.content


def test_the_active_bundle_follows_activations_in_one_request(client, app, worker, dataset):
    from sqlalchemy import update

    from app.store.models import ModelVersion

    enroll_and_retrain(client, worker, dataset)
    r = client.get("/v1/models/active/bundle")
    assert r.status_code == 200 and r.headers["x-model-version"] == "2"
    assert r.content == client.get("/v1/models/2/bundle").content
    again = client.get("/v1/models/active/bundle", headers={"If-None-Match": r.headers["etag"]})
    assert again.status_code == 304 and again.headers["x-model-version"] == "2"
    client.post("/v1/models/1/activate")  # a rollback: the held copy is no longer the active one
    back = client.get("/v1/models/active/bundle", headers={"If-None-Match": r.headers["etag"]})
    assert back.status_code == 200 and back.headers["x-model-version"] == "1"
    with app.state.service.sessions.begin() as s:
        s.execute(update(ModelVersion).values(active=False))
    problem(client.get("/v1/models/active/bundle"), 404, "version")


def test_downloading_an_unknown_version_is_404(client):
    problem(client.get("/v1/models/99/bundle"), 404, "version")


def test_downloading_a_damaged_version_is_409(client, app, worker, dataset):
    from sqlalchemy import update

    from app.store.models import Bundle, ModelVersion

    enroll_and_retrain(client, worker, dataset)
    with app.state.service.sessions.begin() as s:
        sha = s.get(ModelVersion, 2).bundle_sha256
        s.execute(update(Bundle).where(Bundle.sha256 == sha).values(data=b"garbage"))
    assert (
        "the store is damaged"
        in problem(client.get("/v1/models/2/bundle"), 409, "version")["detail"]
    )
    assert client.get("/v1/models/1/bundle").status_code == 200
