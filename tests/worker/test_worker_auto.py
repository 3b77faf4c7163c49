"""A service on the default method ``auto``, started empty: its first model comes from 2
classes of 2 samples whatever order their jobs come in, later touches are named as a fit on
the same samples names them, and refits keep the method chosen until the catalogue grows
or an operator asks for a new choice (``worker/kept_method.py``)."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.data.simulator import simulate_dataset
from app.framework.registry import make_method
from app.testing.service import quick_settings

OBJECTS = ("sponge", "stone", "mug")


@pytest.fixture(scope="module")
def touches():
    """4 simulated objects of 10 trials: the service learns 2 touches of 3 of them."""
    return simulate_dataset(4, 10, seed=8080)


@pytest.fixture
def empty_auto(tmp_path):
    """(client, app, worker) of an ``auto`` service on an empty store (fast ``best``)."""
    from app.api.main import create_app
    from worker import Worker

    settings = quick_settings(
        tmp_path,
        dataset="none",
        method="auto",
        method_params={"best": {"n_estimators": 60, "tuning_rounds": 1}},
    )
    app = create_app(settings)
    with TestClient(app) as client:
        state = app.state.service
        yield client, app, Worker(state.settings, state.sessions, on_activate=state.holder.serve)


def _register(client, touches, k: int) -> dict:
    samples = touches.samples[touches.labels == k][:2].tolist()
    r = client.post("/v1/classes", json={"name": OBJECTS[k], "samples": samples})
    assert r.status_code == 202, r.text
    return r.json()


def _later_touches_named_right(client, touches) -> float:
    rows = np.flatnonzero((touches.labels < 3) & (touches.trials % 10 >= 2))
    r = client.post("/v1/recognize", json={"samples": touches.samples[rows].tolist()})
    assert r.status_code == 200, r.text
    named = [res["class_name"] for res in r.json()["results"]]
    return float(
        np.mean([n == OBJECTS[k] for n, k in zip(named, touches.labels[rows], strict=True)])
    )


def _refit_on_the_same_samples(touches) -> float:
    first = np.r_[[np.flatnonzero(touches.labels == k)[:2] for k in range(3)]].ravel()
    model = make_method("auto", params={"best": {"n_estimators": 60, "tuning_rounds": 1}})
    model = model.fit(touches.subset(first).select_classes(np.arange(3)))
    rows = np.flatnonzero((touches.labels < 3) & (touches.trials % 10 >= 2))
    return float(
        np.mean(model.known_proba(touches.samples[rows]).argmax(1) == touches.labels[rows])
    )


@pytest.mark.parametrize("order", ["all before the first round", "one at a time"])
def test_the_first_model_comes_from_two_samples_a_class_in_any_order(empty_auto, touches, order):
    client, app, worker = empty_auto
    for k in range(3):
        _register(client, touches, k)
        if order == "one at a time":
            worker.run_once()
    worker.run_once()
    jobs = client.get("/v1/jobs", params={"limit": 100}).json()["jobs"]
    assert {j["status"] for j in jobs} == {"succeeded"}, jobs
    active = client.get("/v1/models/active").json()
    assert {c["name"]: c["kind"] for c in active["classes"]} == dict.fromkeys(OBJECTS, "known")
    assert active["method_choice"]["reason"] == "rule"  # 2 trials a class hold no probe
    served = _later_touches_named_right(client, touches)
    assert served >= _refit_on_the_same_samples(touches) - 0.05, served


def test_refits_keep_the_method_until_asked_to_choose_again(empty_auto, touches):
    client, app, worker = empty_auto
    for k in range(2):
        _register(client, touches, k)
    worker.run_once()
    first = client.get("/v1/models/active").json()
    assert first["method_choice"]["n_classes"] == 2 and "kept" not in first["method_choice"]

    _register(client, touches, 2)  # 3 known classes: less than twice the 2 it chose at
    worker.run_once()
    kept = client.get("/v1/models/active").json()
    assert kept["version"] > first["version"] and kept["method"] == first["method"]
    assert kept["method_choice"]["kept"] is True
    assert kept["method_choice"]["kept_since"] == first["version"]

    r = client.post("/v1/models/choice")
    assert r.status_code == 202, r.text
    assert r.json()["kind"] == "choose_method"
    worker.run_once()
    job = client.get(r.headers["Location"]).json()
    assert job["status"] == "succeeded", job
    again = client.get("/v1/models/active").json()
    assert again["version"] == job["model_version"] > kept["version"]
    assert again["reason"] == "method choice"
    assert again["method_choice"]["n_classes"] == 3 and "kept" not in again["method_choice"]
    listed = {m["version"]: m for m in client.get("/v1/models").json()["models"]}
    assert listed[again["version"]]["method_choice"] == again["method_choice"]


def test_a_fixed_method_has_nothing_to_choose(tmp_path):
    from app.api.main import create_app

    app = create_app(quick_settings(tmp_path))  # the quick tests' fixed method
    with TestClient(app) as client:
        r = client.post("/v1/models/choice")
    assert r.status_code == 409 and "not 'auto'" in r.json()["detail"]
