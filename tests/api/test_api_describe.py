"""POST /v1/describe: what a touch feels like, to help describe an object nobody registered."""

from __future__ import annotations

import io

import numpy as np
import pytest

from tests.service_fixtures import problem


def test_each_touch_gets_every_attribute_and_a_suggestion(best_service, best_base):
    client, app, _ = best_service
    model, dataset = best_base
    touches = dataset.samples[[0, 15, 40]]
    r = client.post("/v1/describe", json={"samples": touches.tolist()})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["model_version"] == 1 and len(body["results"]) == 3
    expected = model.attribute_proba(touches)
    names = list(dataset.attribute_names)
    for result, proba in zip(body["results"], expected, strict=True):
        scores = result["attributes"]
        assert sorted(s["name"] for s in scores) == sorted(names)
        assert [s["probability"] for s in scores] == sorted(
            (s["probability"] for s in scores), reverse=True
        )
        assert {s["name"]: s["probability"] for s in scores} == {
            n: float(p) for n, p in zip(names, proba, strict=True)
        }
        likely = [n for n, p in zip(names, proba, strict=True) if p > 0.5] or [
            names[int(proba.argmax())]
        ]
        assert result["suggested"] == likely  # in vocabulary order, ready to register with
    assert body["object"] is None  # unless the touches are said to be of one object

    # several touches of one object: one description from their mean too
    one = client.post(
        "/v1/describe",
        params={"same_object": "true"},
        json={"samples": dataset.samples[:3].tolist()},
    ).json()["object"]
    mean = model.attribute_proba(dataset.samples[:3]).mean(axis=0)
    assert {s["name"]: s["probability"] for s in one["attributes"]} == pytest.approx(
        {n: float(p) for n, p in zip(names, mean, strict=True)}
    )
    assert one["suggested"] == (
        [n for n, p in zip(names, mean, strict=True) if p > 0.5] or [names[int(mean.argmax())]]
    )

    # the same touches as .npy answer the same
    buf = io.BytesIO()
    np.save(buf, touches.astype(np.float32))
    npy = client.post(
        "/v1/describe", content=buf.getvalue(), headers={"Content-Type": "application/x-npy"}
    )
    assert npy.json() == body


def test_the_attributes_predicted_for_training_touches_are_their_objects(best_base):
    """On the objects it was trained on the classifiers are nearly right (PHAC-2's unseen
    objects are much harder: docs/RESULTS.md)."""
    from sklearn.metrics import roc_auc_score

    model, dataset = best_base
    proba = model.attribute_proba(dataset.samples)
    truth = dataset.class_attributes[dataset.labels]
    varying = [j for j in range(truth.shape[1]) if 0 < truth[:, j].mean() < 1]
    assert np.mean([roc_auc_score(truth[:, j], proba[:, j]) for j in varying]) > 0.9


def test_methods_without_attribute_classifiers_say_so(client, sample):
    body = problem(client.post("/v1/describe", json={"samples": [sample]}), 409, "model")
    assert "does not predict attributes" in body["detail"]


def test_bad_touches_are_named(best_service):
    client, _, _ = best_service
    problem(client.post("/v1/describe", json={"samples": [[0.0]]}), 422, "samples[0]")
    problem(client.post("/v1/describe", json={"samples": []}), 422)
    problem(
        client.post(
            "/v1/describe", content=b"not json", headers={"Content-Type": "application/json"}
        ),
        422,
    )
