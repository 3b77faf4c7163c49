"""Withdrawn classes and samples leave the served model, and nothing else changes."""

from __future__ import annotations

import numpy as np
import pytest

from app.framework.errors import UnsupportedOperationError
from app.store import repo
from app.testing.service import unused_vectors
from tests.service_fixtures import add_sample, job, register
from worker import retrain


def withdraw(client, path: str) -> dict:
    r = client.delete(path)
    assert r.status_code == 202, r.text
    return r.json()["job"]


def served(app):
    return app.state.service.holder.current.recognizer


def test_a_withdrawn_sample_leaves_the_model_and_the_class_stays(client, app, worker, dataset):
    cid = register(client, dataset, "mug")["class"]["id"]
    kept = add_sample(client, cid, dataset.samples[0] + 0.01)["sample_id"]
    wrong = add_sample(client, cid, dataset.samples[-1])["sample_id"]
    worker.run_once()
    assert len(served(app).registry.novel_samples["mug"]) == 2

    withdrawal = withdraw(client, f"/v1/classes/{cid}/samples/{wrong}")
    assert worker.run_once() == 1
    done = job(client, withdrawal["id"])
    active = client.get("/v1/models/active").json()
    assert done["status"] == "succeeded" and done["model_version"] == active["version"]
    assert active["reason"] == "withdrawal"
    with app.state.service.sessions() as s:
        assert repo.get_version(s, active["version"]).sample_ids == [kept]
    shots = served(app).registry.novel_samples["mug"]
    assert len(shots) == 1 and np.allclose(shots[0], dataset.samples[0] + 0.01)
    assert client.get(f"/v1/classes/{cid}").json()["in_active_model"] is True


def test_a_withdrawn_class_is_never_answered_again(client, app, worker, dataset):
    mug = register(client, dataset, "mug", 0)["class"]["id"]
    register(client, dataset, "cup", 1)
    add_sample(client, mug, dataset.samples[0])
    worker.run_once()
    assert "mug" in served(app).registry.novel_names

    withdraw(client, f"/v1/classes/{mug}")
    assert worker.run_once() == 1
    model = served(app)
    assert "mug" not in model.registry.all_names and "mug" not in model.registry.novel_samples
    assert model.registry.novel_names == ["cup"]
    active = client.get("/v1/models/active").json()
    assert "mug" not in {c["name"] for c in active["classes"]} and active["reason"] == "withdrawal"
    r = client.post("/v1/recognize", json={"samples": dataset.samples[:20].tolist()})
    answered = {s["class_name"] for res in r.json()["results"] for s in res["top_k"]}
    assert "mug" not in answered and answered


def test_a_withdrawn_class_registered_again_is_served_with_its_new_attributes(
    client, app, worker, dataset
):
    first = register(client, dataset, "mug", 0)["class"]["id"]
    worker.run_once()
    withdraw(client, f"/v1/classes/{first}")
    again = register(client, dataset, "mug", 1)  # both are folded into one round
    assert again["class"]["id"] == first
    assert worker.run_once() == 2
    assert job(client, again["job"]["id"])["status"] == "succeeded"
    reg = served(app).registry
    vector = reg.novel_attributes[reg.novel_names.index("mug")]
    assert vector.tolist() == unused_vectors(dataset, 2)[1]
    assert client.get(f"/v1/classes/{first}").json()["in_active_model"] is True


def test_enrolments_of_what_was_withdrawn_before_training_fail_and_change_nothing(
    client, app, worker, dataset
):
    created = register(client, dataset, "mug")
    cid = created["class"]["id"]
    sample = add_sample(client, cid, dataset.samples[0])
    withdrawal = withdraw(client, f"/v1/classes/{cid}")
    assert worker.run_once() == 3
    for queued in (created["job"], sample["job"]):
        failed = job(client, queued["id"])
        assert failed["status"] == "failed" and f"class {cid} was withdrawn" in failed["error"]
    done = job(client, withdrawal["id"])
    assert done["status"] == "succeeded" and done["model_version"] == 1  # no retrain was needed
    assert client.get("/v1/models/active").json()["version"] == 1


def test_a_sample_withdrawn_before_training_fails_its_own_job_only(client, app, worker, dataset):
    created = register(client, dataset, "mug")
    cid = created["class"]["id"]
    wrong = add_sample(client, cid, dataset.samples[0])
    withdraw(client, f"/v1/classes/{cid}/samples/{wrong['sample_id']}")
    worker.run_once()
    failed = job(client, wrong["job"]["id"])
    assert (
        failed["status"] == "failed"
        and f"sample {wrong['sample_id']} was withdrawn" in failed["error"]
    )
    assert job(client, created["job"]["id"])["status"] == "succeeded"
    assert "mug" in served(app).registry.novel_names
    assert "mug" not in served(app).registry.novel_samples


def test_a_promoted_class_below_the_threshold_again_is_novel_again(client, app, worker, dataset):
    app.state.service.settings.promotion_threshold = 2
    cid = register(client, dataset, "promoted")["class"]["id"]
    first = add_sample(client, cid, dataset.samples[0] + 0.01)["sample_id"]
    add_sample(client, cid, dataset.samples[1] + 0.01)
    worker.run_once()
    assert client.get(f"/v1/classes/{cid}").json()["kind"] == "known"
    assert "promoted" in served(app).registry.known_names

    withdraw(client, f"/v1/classes/{cid}/samples/{first}")
    assert worker.run_once() == 1
    cls = client.get(f"/v1/classes/{cid}").json()
    assert cls["kind"] == "novel" and cls["n_samples"] == 1 and cls["in_active_model"] is True
    reg = served(app).registry
    assert "promoted" in reg.novel_names and "promoted" not in reg.known_names
    assert len(reg.novel_samples["promoted"]) == 1
    assert len(reg.known_names) == dataset.n_classes
    assert client.get("/v1/models/active").json()["reason"] == "withdrawal"


def test_best_withdraws_from_its_novel_part_without_fitting_again(
    best_service, best_base, monkeypatch
):
    client, app, worker = best_service
    base, dataset = best_base
    mug = register(client, dataset, "mug", 0)["class"]["id"]
    cup = register(client, dataset, "cup", 1)["class"]["id"]
    bowl = register(client, dataset, "bowl", 2)["class"]["id"]
    shots = {
        name: [add_sample(client, cid, dataset.samples[k] + 0.01)["sample_id"] for k in (3, 4)]
        for name, cid in (("mug", mug), ("cup", cup))
    }
    worker.run_once()

    def no_fit(*args, **kwargs):
        raise AssertionError("a withdrawal from the novel part must not fit the model again")

    monkeypatch.setattr(retrain, "fit_in_child", no_fit)
    withdraw(client, f"/v1/classes/{mug}/samples/{shots['mug'][0]}")
    withdraw(client, f"/v1/classes/{bowl}")
    assert worker.run_once() == 2
    active = client.get("/v1/models/active").json()
    assert active["reason"] == "withdrawal" and active["class_count"] == dataset.n_classes + 2

    # the same model as one built from scratch on what is left
    reference = base.add_novel_classes(
        ["mug", "cup"],
        np.stack([unused_vectors(dataset, 2)[0], unused_vectors(dataset, 2)[1]]).astype(np.float32),
    )
    reference = reference.add_one_shot("mug", dataset.samples[4:5] + 0.01)
    reference = reference.add_one_shot("cup", dataset.samples[3:5] + 0.01)
    served = app.state.service.holder.current.recognizer
    assert served.registry.novel_names == ["mug", "cup"]
    x = dataset.samples[::3]
    assert np.allclose(served.novel_proba(x), reference.novel_proba(x))
    assert np.allclose(served.known_proba(x), base.known_proba(x))
    assert np.array_equal(served.is_novel(x), base.is_novel(x))


def test_only_separable_methods_drop_their_novel_classes(best_base, base_model):
    best, dataset = best_base
    with_novel = best.add_novel_classes(["mug"], np.asarray(unused_vectors(dataset, 1), np.float32))
    dropped = with_novel.without_novel_classes()
    assert dropped.registry.novel_names == [] and with_novel.registry.novel_names == ["mug"]
    with pytest.raises(UnsupportedOperationError, match="fit it again"):
        base_model[0].without_novel_classes()  # the paper's one-shot step tunes its generator
