"""A service whose method is ``prototypes``: enrolments through the HTTP API and the worker
become model versions without a refit (zero-shot, one-shot, promotion), and samples that lack
procedures are answered with the procedure to do next."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.data.procedures import keep_only
from app.framework.registry import make_method
from app.testing.service import quick_dataset, quick_settings
from tests.service_fixtures import add_sample, register

PARAMS = {"seed": 0}


@pytest.fixture(scope="module")
def prototypes_base():
    dataset = quick_dataset()
    return make_method("prototypes", **PARAMS).fit(dataset), dataset


@pytest.fixture
def prototypes_service(tmp_path, prototypes_base):
    from app.api.main import create_app
    from worker import Worker

    app = create_app(
        quick_settings(tmp_path, method="prototypes", method_params={"prototypes": PARAMS}),
        trainer=lambda: prototypes_base,
    )
    with TestClient(app) as client:
        state = app.state.service
        yield client, app, Worker(state.settings, state.sessions, on_activate=state.holder.serve)


def test_enrolments_go_live_without_a_refit(prototypes_service, prototypes_base):
    client, app, worker = prototypes_service
    dataset = prototypes_base[1]
    active = client.get("/v1/models/active").json()
    assert active["method"] == "prototypes"
    fitted = app.state.service.holder.current.recognizer
    settings = app.state.service.settings
    settings.promotion_threshold = 2
    created = register(client, dataset, "mug")
    cid = created["class"]["id"]
    assert worker.run_once() == 1
    served = app.state.service.holder.current.recognizer
    assert "mug" in served.registry.novel_names
    # the fit's own figures, carried on: no version here was fitted again
    assert served.metrics["timings"] == fitted.metrics["timings"]
    sample = dataset.samples[0] + 0.02
    add_sample(client, cid, sample)
    worker.run_once()
    served = app.state.service.holder.current.recognizer
    assert served.shot_has_[served.registry.novel_names.index("mug")]
    add_sample(client, cid, dataset.samples[1] + 0.02)
    worker.run_once()
    assert client.get(f"/v1/classes/{cid}").json()["kind"] == "known"
    served = app.state.service.holder.current.recognizer
    assert served.registry.known_names[-1] == "mug"
    assert served.metrics["n_grown_samples"] == 2
    assert served.metrics["timings"] == fitted.metrics["timings"]
    assert len(served.search_) == len(fitted.search_) + 1  # the promoted class's prototype
    r = client.post("/v1/recognize", json={"samples": [np.asarray(sample).tolist()]})
    assert r.status_code == 200, r.text


def test_a_sample_that_lacks_procedures_is_answered_with_the_next_one(
    prototypes_service, prototypes_base
):
    client, _, _ = prototypes_service
    model, dataset = prototypes_base
    active = client.get("/v1/models/active").json()
    assert active["first_procedure"] in model.procedures
    first = model.procedures.index(active["first_procedure"])
    part = keep_only(dataset.samples[:1], model.procedures, [first])[0]
    body = {"samples": [[None if np.isnan(row).all() else row.tolist() for row in part]]}
    r = client.post("/v1/recognize", json=body)
    assert r.status_code == 200, r.text
    (answer,) = r.json()["results"]
    assert answer["procedures_used"] == [active["first_procedure"]]
    assert answer["next_procedure"] in model.procedures  # one procedure never suffices
