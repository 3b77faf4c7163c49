"""Input health over HTTP: every answer of ``POST /v1/recognize`` carries ``input_outlier``
and ``input_outlier_score`` (documented in the OpenAPI schema), and ``/metrics`` exports the
outliers and each channel's drift over the last ``TACTILE_INPUT_WINDOW`` samples."""

from __future__ import annotations

import re

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.api.main import create_app
from app.api.schemas import RecognizeResponse
from app.framework.input_health import OUTLIER_THRESHOLD
from app.testing.service import quick_settings
from tests.service_fixtures import live_channel, npy

NPY = {"content-type": "application/x-npy"}


def gauge(text: str, name: str, labels: str = "") -> float:
    """The value of one series of ``name`` in a Prometheus text exposition."""
    pattern = rf"^{re.escape(name)}{re.escape(labels)} (\S+)$"
    found = re.search(pattern, text, re.MULTILINE)
    assert found, f"{name}{labels} is not in /metrics"
    return float(found.group(1))


def test_each_answer_carries_its_input_health(client, dataset):
    x = dataset.samples[:2]
    broken = np.stack([np.zeros_like(x[0]), x[0] * 1e6, x[0]])
    broken[2, live_channel(dataset)] = 0.0  # one dead channel
    r = client.post("/v1/recognize", json={"samples": np.concatenate([x, broken]).tolist()})
    assert r.status_code == 200
    body = r.json()
    RecognizeResponse.model_validate(body)
    health = [(a["input_outlier"], a["input_outlier_score"]) for a in body["results"]]
    assert [h[0] for h in health] == [False, False, True, True, True]
    assert all(s <= OUTLIER_THRESHOLD for _, s in health[:2])
    assert all(s > OUTLIER_THRESHOLD for _, s in health[2:])
    # the same answers from a .npy body, and fused over touches of one object
    r = client.post("/v1/recognize", content=npy(broken), headers=NPY)
    assert [a["input_outlier"] for a in r.json()["results"]] == [True, True, True]
    r = client.post(
        "/v1/recognize",
        json={"samples": [x[0].tolist(), broken[0].tolist()]},
        params={"same_object": True},
    )
    assert r.json()["results"][0]["input_outlier"] is True


def test_the_schema_documents_the_fields(client):
    schema = client.get("/openapi.json").json()["components"]["schemas"]["RecognitionOut"]
    for name in ("input_outlier", "input_outlier_score"):
        assert name in schema["properties"] and name in schema["required"]
        assert "training" in schema["properties"][name]["description"]
    assert f"{OUTLIER_THRESHOLD:g} " in schema["properties"]["input_outlier"]["description"]


def test_metrics_count_outliers(client, dataset):
    x = dataset.samples[:3]
    client.post("/v1/recognize", json={"samples": x.tolist()})
    client.post("/v1/recognize", json={"samples": np.zeros_like(x[:2]).tolist()})
    text = client.get("/metrics").text
    assert gauge(text, "tactile_input_outliers_total") == 2.0
    assert gauge(text, "tactile_input_window_samples") == 5.0
    assert gauge(text, "tactile_input_outlier_rate") == pytest.approx(0.4)
    assert "# HELP tactile_input_drift " in text


def test_metrics_show_a_drifting_channel_over_the_window(tmp_path, base_model):
    """A window of 8 samples: sound ones, then ones whose channel 3 is dead, then sound ones
    again; the drift of channel 3 rises and falls with the window, the others stay low (a
    window of 8 samples: under 2 training IQRs from the middle)."""
    model, dataset = base_model
    settings = quick_settings(tmp_path / "d", input_window=8)
    sound = dataset.samples[:: len(dataset) // 8][:8]  # touches of 8 objects
    dead = sound.copy()
    dead[:, 3] = dead[:, 3, :1]  # stuck at its first value
    with TestClient(create_app(settings, trainer=lambda: base_model)) as c:

        def drift_after(samples: np.ndarray) -> tuple[np.ndarray, float]:
            for s in samples:  # one touch per request, as a robot sends them
                assert c.post("/v1/recognize", json={"samples": [s.tolist()]}).status_code == 200
            text = c.get("/metrics").text
            drift = [gauge(text, "tactile_input_drift", f'{{channel="{i}"}}') for i in range(32)]
            return np.array(drift), gauge(text, "tactile_input_outlier_rate")

        drift, rate = drift_after(sound)
        assert drift.max() < 2.0 and rate == 0.0
        drift, rate = drift_after(dead)
        assert drift.argmax() == 3 and drift[3] > 10 and rate == 1.0
        assert np.delete(drift, 3).max() < 2.0
        drift, rate = drift_after(sound[:4])  # half the window
        assert rate == 0.5
        drift, rate = drift_after(sound[4:])
        assert drift.max() < 2.0 and rate == 0.0


def test_the_window_keeps_each_sample_of_fused_answers(base_model):
    """Touches fused into one answer: the answer counts once among the outliers, and the
    window keeps each touch with its own verdict."""
    from app.service.input_monitor import InputMonitor
    from app.service.metrics import Metrics

    model, dataset = base_model
    x = dataset.samples[:3].copy()
    x[1] = 0.0
    batch = model.recognize_batch(x, groups=np.array([0, 0, 1]))
    assert batch.input_outlier.tolist() == [True, False]
    metrics = Metrics()
    monitor = InputMonitor(metrics, window=4)
    monitor.observe(batch, model.input_profile_)
    monitor.refresh()
    assert metrics.input_outliers._value.get() == 1.0
    assert metrics.input_window_samples._value.get() == 3.0
    assert metrics.input_outlier_rate._value.get() == pytest.approx(1 / 3)
    # a window of 4 keeps the last 4 samples
    monitor.observe(model.recognize_batch(dataset.samples[3:6]), model.input_profile_)
    monitor.refresh()
    assert metrics.input_window_samples._value.get() == 4.0
    assert metrics.input_outlier_rate._value.get() == 0.0


def broken_of(channel: int, x: np.ndarray) -> np.ndarray:
    """Zeros, a saturated sensor and one dead channel, made from sound sample ``x``."""
    dead = x.copy()
    dead[channel] = 0.0
    return np.stack([np.zeros_like(x), np.full_like(x, float(np.abs(x).max()) * 1e3), dead])


def abstained(result: dict) -> bool:
    """The answer names no object: it abstained on an input outlier."""
    return (
        result["kind"] == "input_outlier"
        and result["class_name"] is None
        and result["class_id"] is None
        and result["is_novel"] is None
        and result["top_k"] == []
        and result["input_outlier"] is True
    )


def test_a_broken_sensor_is_not_answered_as_an_object(client, dataset):
    sound = dataset.samples[:2]
    broken = broken_of(live_channel(dataset), sound[0])
    x = np.concatenate([sound, broken])
    r = client.post("/v1/recognize", json={"samples": x.tolist()})
    assert r.status_code == 200
    results = RecognizeResponse.model_validate(r.json()).model_dump()["results"]
    assert [abstained(a) for a in results] == [False, False, True, True, True]
    assert all(a["kind"] in ("known", "novel") and a["class_name"] for a in results[:2])
    # .npy bodies, one sample alone, and touches fused with one broken among them
    r = client.post("/v1/recognize", content=npy(broken), headers=NPY)
    assert [abstained(a) for a in r.json()["results"]] == [True, True, True]
    r = client.post("/v1/recognize", content=npy(broken[2]), headers=NPY)
    assert abstained(r.json()["results"][0])
    r = client.post(
        "/v1/recognize",
        json={"samples": [sound[0].tolist(), broken[2].tolist()]},
        params={"same_object": True},
    )
    assert abstained(r.json()["results"][0])

    # the model's guess on request, flagged; sound samples answered alike either way
    r = client.post("/v1/recognize", json={"samples": x.tolist()}, params={"outliers": "answer"})
    guessed = r.json()["results"]
    assert all(a["kind"] in ("known", "novel") and a["class_name"] for a in guessed)
    assert [a["input_outlier"] for a in guessed] == [False, False, True, True, True]
    assert guessed[:2] == results[:2]
    r = client.post("/v1/recognize", json={"samples": x.tolist()}, params={"outliers": "abstain"})
    assert r.json()["results"] == results


def test_an_unknown_outlier_policy_is_a_422_naming_it(client, sample):
    r = client.post("/v1/recognize", json={"samples": [sample]}, params={"outliers": "guess"})
    assert r.status_code == 422
    assert r.headers["content-type"].startswith("application/problem+json")
    assert "outliers" in r.json()["detail"] and "abstain, answer" in r.json()["detail"]


def test_the_setting_answers_outliers_for_every_request(tmp_path, base_model):
    model, dataset = base_model
    broken = broken_of(live_channel(dataset), dataset.samples[0])
    settings = quick_settings(tmp_path / "o", outliers="answer")
    with TestClient(create_app(settings, trainer=lambda: base_model)) as c:
        results = c.post("/v1/recognize", json={"samples": broken.tolist()}).json()["results"]
        assert all(a["class_name"] and a["input_outlier"] for a in results)
        r = c.post(
            "/v1/recognize", json={"samples": broken.tolist()}, params={"outliers": "abstain"}
        )
        assert all(abstained(a) for a in r.json()["results"])


def test_the_schema_documents_the_abstention(client):
    doc = client.get("/openapi.json").json()
    out = doc["components"]["schemas"]["RecognitionOut"]["properties"]
    assert "input_outlier" in out["kind"]["enum"]
    assert {"type": "null"} in out["class_name"]["anyOf"]
    assert {"type": "null"} in out["is_novel"]["anyOf"]
    params = doc["paths"]["/v1/recognize"]["post"]["parameters"]
    (outliers,) = [p for p in params if p["name"] == "outliers"]
    assert outliers["schema"]["enum"] == ["abstain", "answer"]
    assert "TACTILE_OUTLIERS" in outliers["description"]
