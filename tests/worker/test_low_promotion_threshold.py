"""A service whose promotion threshold is low (3): a class registered with that many
samples and no description, and one learnt from samples alone that reaches it later, both
end as known classes recognised from their samples. Such a class has no attribute vector:
learning it into the known part gives it none (not known), as its registration did."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from app.data.simulator import simulate_dataset
from app.testing.service import BEST_PARAMS, quick_settings


@pytest.fixture(scope="module")
def touches():
    """A simulated object the service's dataset lacks (another seed), 6 touches."""
    return simulate_dataset(n_objects=1, trials_per_object=6, seed=4242)


@pytest.fixture
def service(tmp_path, best_base):
    """(client, worker) of a ``best`` service promoting at 3 samples, which it learns into
    its known part without a refit (the default ``grow_fraction``: 3 samples are well
    within a quarter of the 60 it was fitted on)."""
    from app.api.main import create_app
    from worker import Worker

    settings = quick_settings(
        tmp_path,
        method="best",
        method_params={"best": BEST_PARAMS},
        promotion_threshold=3,
    )
    app = create_app(settings, trainer=lambda: best_base)
    with TestClient(app) as client:
        state = app.state.service
        yield client, Worker(state.settings, state.sessions, on_activate=state.holder.serve)


def _jobs(client) -> list[dict]:
    return client.get("/v1/jobs", params={"limit": 100}).json()["jobs"]


def _recognised_as_known(client, touches) -> None:
    """'felt' is a known class of the active model (promoted: a new version) and its
    later touches are named 'felt'."""
    active = client.get("/v1/models/active").json()
    kinds = {c["name"]: c["kind"] for c in active["classes"]}
    assert kinds["felt"] == "known", kinds
    assert active["reason"] == "promotion", active["reason"]
    r = client.post("/v1/recognize", json={"samples": touches.samples[3:].tolist()})
    assert r.status_code == 200, r.text
    named = [res["class_name"] for res in r.json()["results"]]
    assert named.count("felt") >= 2, named


def test_registered_with_threshold_samples_and_no_description(service, touches):
    client, worker = service
    r = client.post("/v1/classes", json={"name": "felt", "samples": touches.samples[:3].tolist()})
    assert r.status_code == 202, r.text
    worker.run_once()
    jobs = _jobs(client)
    assert {j["status"] for j in jobs} == {"succeeded"}, jobs
    _recognised_as_known(client, touches)


def test_learnt_from_samples_alone_then_promoted(service, touches):
    client, worker = service
    r = client.post("/v1/classes", json={"name": "felt", "samples": touches.samples[:2].tolist()})
    assert r.status_code == 202, r.text
    cid = r.json()["class"]["id"]
    worker.run_once()
    r = client.post(f"/v1/classes/{cid}/samples", json={"sample": touches.samples[2].tolist()})
    assert r.status_code == 202, r.text
    worker.run_once()
    jobs = _jobs(client)
    assert {j["status"] for j in jobs} == {"succeeded"}, jobs
    _recognised_as_known(client, touches)
