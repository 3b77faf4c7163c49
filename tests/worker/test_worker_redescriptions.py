"""A class described anew (PATCH) is served with its new attributes and keeps its samples."""

from __future__ import annotations

import numpy as np

from app.framework.recognizer import TactileRecognizer
from app.testing.service import unused_vectors
from tests.service_fixtures import add_sample, job, register
from worker import retrain


def redescribe(client, class_id: int, vector: list[int]) -> dict:
    r = client.patch(f"/v1/classes/{class_id}", json={"attribute_vector": vector})
    assert r.status_code == 202, r.text
    return r.json()["job"]


def served(app):
    return app.state.service.holder.current.recognizer


def test_the_served_model_takes_the_new_attributes_and_keeps_the_samples(
    client, app, worker, dataset
):
    cid = register(client, dataset, "mug", 0)["class"]["id"]
    add_sample(client, cid, dataset.samples[0] + 0.01)
    worker.run_once()
    vector = unused_vectors(dataset, 2)[1]
    update = redescribe(client, cid, vector)
    assert worker.run_once() == 1
    done = job(client, update["id"])
    active = client.get("/v1/models/active").json()
    assert done["status"] == "succeeded" and done["model_version"] == active["version"] == 3
    assert active["reason"] == "update"
    reg = served(app).registry
    assert reg.novel_attributes[reg.novel_names.index("mug")].tolist() == vector
    shots = reg.novel_samples["mug"]
    assert len(shots) == 1 and np.allclose(shots[0], dataset.samples[0] + 0.01)


def test_the_same_description_again_changes_no_model(client, app, worker, dataset):
    cid = register(client, dataset, "mug", 0)["class"]["id"]
    worker.run_once()
    update = redescribe(client, cid, unused_vectors(dataset, 1)[0])
    assert worker.run_once() == 1
    assert job(client, update["id"])["model_version"] == 2  # already served as it is described
    assert client.get("/v1/models/active").json()["version"] == 2


def test_a_redescription_of_what_is_gone_or_never_enrolled_fails(
    client, worker, dataset, monkeypatch
):
    mug = register(client, dataset, "mug", 0)["class"]["id"]
    update = redescribe(client, mug, unused_vectors(dataset, 3)[2])
    assert client.delete(f"/v1/classes/{mug}").status_code == 202
    worker.run_once()
    failed = job(client, update["id"])
    assert failed["status"] == "failed" and f"class {mug} was withdrawn" in failed["error"]

    cup = register(client, dataset, "cup", 1)
    with monkeypatch.context() as m:  # its registration fails
        m.setattr(
            TactileRecognizer,
            "add_novel_classes",
            lambda *a, **k: (_ for _ in ()).throw(RuntimeError("out of memory")),
        )
        worker.run_once()
    assert job(client, cup["job"]["id"])["status"] == "failed"
    update = redescribe(client, cup["class"]["id"], unused_vectors(dataset, 4)[3])
    worker.run_once()
    failed = job(client, update["id"])
    assert failed["status"] == "failed" and "registration failed" in failed["error"]


def test_a_promoted_class_described_anew_is_fitted_again(client, app, worker, dataset):
    app.state.service.settings.promotion_threshold = 2
    cid = register(client, dataset, "promoted")["class"]["id"]
    for k in (0, 1):
        add_sample(client, cid, dataset.samples[k] + 0.01)
    worker.run_once()
    assert client.get(f"/v1/classes/{cid}").json()["kind"] == "known"
    vector = unused_vectors(dataset, 2)[1]
    redescribe(client, cid, vector)
    assert worker.run_once() == 1
    reg = served(app).registry
    assert reg.known_attributes[reg.known_names.index("promoted")].tolist() == vector
    cls = client.get(f"/v1/classes/{cid}").json()
    assert cls["kind"] == "known" and cls["n_samples"] == 2
    assert client.get("/v1/models/active").json()["reason"] == "update"


def test_best_takes_new_attributes_without_fitting_again(best_service, best_base, monkeypatch):
    client, app, worker = best_service
    base, dataset = best_base
    mug = register(client, dataset, "mug", 0)["class"]["id"]
    register(client, dataset, "cup", 1)
    add_sample(client, mug, dataset.samples[3] + 0.01)
    worker.run_once()

    def no_fit(*args, **kwargs):
        raise AssertionError("new attributes of a novel class must not fit the model again")

    monkeypatch.setattr(retrain, "fit_in_child", no_fit)
    vectors = unused_vectors(dataset, 3)
    redescribe(client, mug, vectors[2])
    assert worker.run_once() == 1
    # the same model as one built from scratch with the new description
    reference = base.add_novel_classes(["mug", "cup"], np.float32([vectors[2], vectors[1]]))
    reference = reference.add_one_shot("mug", dataset.samples[3:4] + 0.01)
    x = dataset.samples[::3]
    assert served(app).registry.novel_names == ["mug", "cup"]
    assert np.allclose(served(app).novel_proba(x), reference.novel_proba(x))
