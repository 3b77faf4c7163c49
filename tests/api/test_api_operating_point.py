"""Every answer of ``POST /v1/recognize`` says which operating point routed it: the
threshold it used (``novelty_threshold``), the share of held-out known touches that
threshold kept at fit (``known_kept``: 0.90 by default for every method, the request's or
``TACTILE_KNOWN_KEPT`` otherwise) and ``operating_point``; a model without a calibration
curve answers at its own threshold (``model_default``)."""

from __future__ import annotations

import copy

import pytest
from fastapi.testclient import TestClient

from app.api.main import create_app
from app.api.schemas import RecognizeResponse
from app.framework.recognizer import DEFAULT_KNOWN_KEPT
from app.testing.service import quick_settings
from tests.service_fixtures import npy

NPY = {"content-type": "application/x-npy"}


def routed_by(results: list[dict], threshold: float) -> bool:
    """Each answer was routed by ``threshold``: novel exactly where its score is above."""
    return all(
        r["novelty_threshold"] == threshold and r["is_novel"] == (r["novelty_score"] > threshold)
        for r in results
    )


def test_the_default_operating_point_is_090_of_known_touches_for_every_method(
    client, app, best_service, dataset
):
    assert DEFAULT_KNOWN_KEPT == 0.90
    x = dataset.samples[::7][:8]
    for c, a in ((client, app), best_service[:2]):
        rec = a.state.service.holder.current.recognizer
        at_090 = rec.threshold_keeping(0.90)
        body = c.post("/v1/recognize", json={"samples": x.tolist()}).json()
        RecognizeResponse.model_validate(body)
        results = body["results"]
        assert {(r["known_kept"], r["operating_point"]) for r in results} == {(0.9, "known_kept")}
        assert routed_by(results, at_090)
        # one sample, a .npy body and fused touches say the same
        one = c.post("/v1/recognize", content=npy(x[0]), headers=NPY).json()["results"]
        assert routed_by(one, at_090) and one[0]["known_kept"] == 0.9
        fused = c.post(
            "/v1/recognize", json={"samples": x[:3].tolist()}, params={"same_object": True}
        ).json()["results"]
        assert fused[0]["known_kept"] == 0.9 and fused[0]["novelty_threshold"] is not None


def test_a_requested_operating_point_is_the_one_reported(client, app, dataset):
    rec = app.state.service.holder.current.recognizer
    x = dataset.samples[::5][:10]
    body = client.post(
        "/v1/recognize", json={"samples": x.tolist()}, params={"known_kept": 0.97}
    ).json()
    assert {r["known_kept"] for r in body["results"]} == {0.97}
    assert routed_by(body["results"], rec.threshold_keeping(0.97))
    assert rec.threshold_keeping(0.97) >= rec.threshold_keeping(0.90)


def test_a_model_without_a_calibration_curve_answers_at_its_own_threshold(tmp_path, base_model):
    model, dataset = base_model
    bare = copy.copy(model)
    bare.novelty_tuning = None
    settings = quick_settings(tmp_path / "m")
    with TestClient(create_app(settings, trainer=lambda: (bare, dataset))) as c:
        r = c.post("/v1/recognize", json={"samples": dataset.samples[:3].tolist()})
        assert r.status_code == 200
        results = r.json()["results"]
        assert {(r["known_kept"], r["operating_point"]) for r in results} == {
            (None, "model_default")
        }
        assert routed_by(results, bare.novelty_threshold)


@pytest.mark.parametrize("name", ["novelty_threshold", "known_kept", "operating_point"])
def test_the_schema_documents_the_operating_point(client, name):
    schema = client.get("/openapi.json").json()["components"]["schemas"]["RecognitionOut"]
    assert name in schema["properties"] and name in schema["required"]
    assert len(schema["properties"][name]["description"]) > 40


def test_touches_of_one_object_read_the_curve_of_as_many_touches(best_service, best_base):
    c, a = best_service[:2]
    tuning = a.state.service.holder.current.recognizer.novelty_tuning
    x = best_base[1].samples[:3]
    (fused,) = c.post(
        "/v1/recognize", json={"samples": x.tolist()}, params={"same_object": True}
    ).json()["results"]
    threshold, k = tuning.threshold_keeping_touches(0.9, 3)
    assert (fused["novelty_threshold"], fused["calibrated_touches"]) == (threshold, k or 1)
    assert fused["is_novel"] == (fused["novelty_score"] > threshold)
    each = c.post("/v1/recognize", json={"samples": x.tolist()}).json()["results"]
    assert {(r["novelty_threshold"], r["calibrated_touches"]) for r in each} == {
        (tuning.threshold_keeping(0.9), 1)
    }
