"""Enrolment mistakes are named: a second spelling of a class name is a 409 naming the
class that has it, and a sample the served model gives to another class with high
confidence is kept with a warning, in the 202 and on its job."""

from __future__ import annotations

import numpy as np

from app.service.enrolment import DOUBT_PROBABILITY
from tests.service_fixtures import problem, register


def test_a_name_differing_only_in_case_or_spaces_is_409_naming_the_class(client, dataset):
    first = register(client, dataset, "foam-block")["class"]
    for name in ("Foam-Block", "  FOAM-BLOCK "):
        body = problem(client.post("/v1/classes", json={"name": name, "attributes": ["hard"]}), 409)
        assert body["errors"] == [{"field": "name", "reason": body["detail"]}]
        assert body["detail"] == (
            f"a class named 'foam-block' already exists (class {first['id']}; names are "
            "compared without regard to case): add samples to it, or choose another name"
        )
    names = [c["name"] for c in client.get("/v1/classes?limit=100").json()["classes"]]
    assert names.count("foam-block") == 1 and "Foam-Block" not in names


def test_a_sample_given_to_another_class_is_kept_with_a_warning(best_stores_service, best_base):
    client, _, worker = best_stores_service
    _, dataset = best_base
    cls = register(client, dataset, "foam-block")["class"]
    worker.run_once()  # the class is in the served model
    assert client.get(f"/v1/classes/{cls['id']}").json()["in_active_model"]
    x = dataset.samples[0]  # a training sample of a known class: answered as it, surely
    r = client.post(f"/v1/classes/{cls['id']}/samples", json={"sample": x.tolist()})
    assert r.status_code == 202, r.text
    body = r.json()
    known = dataset.class_names[dataset.labels[0]]
    top = body["recognized_as"]["top_k"][0]
    assert top["class_name"] == known and top["probability"] >= DOUBT_PROBABILITY
    (warning,) = body["warnings"]
    assert f"recognises this sample as '{known}'" in warning and "not as 'foam-block'" in warning
    assert "withdraw it" in warning
    assert body["job"]["warnings"] == body["warnings"]
    job = client.get(f"/v1/jobs/{body['job']['id']}").json()
    assert job["warnings"] == body["warnings"]
    assert client.get(f"/v1/classes/{cls['id']}").json()["n_samples"] == 1  # kept all the same


def test_a_sample_the_model_gives_to_its_own_class_earns_no_warning(best_stores_service, best_base):
    client, _, worker = best_stores_service
    _, dataset = best_base
    # an object of its own: the known samples moved far off, learnt from its samples
    own = (dataset.samples[:3] + 5 * dataset.samples.std()).astype(np.float32)
    r = client.post("/v1/classes", json={"name": "steel vase", "samples": own.tolist()})
    assert r.status_code == 202, r.text
    worker.run_once()
    cid = r.json()["class"]["id"]
    body = client.post(f"/v1/classes/{cid}/samples", json={"sample": own[0].tolist()}).json()
    top = body["recognized_as"]["top_k"][0]
    assert top["class_name"] == "steel vase", body  # its own class: no doubt
    assert body["warnings"] == [] and body["job"]["warnings"] == []
    assert client.get(f"/v1/jobs/{body['job']['id']}").json()["warnings"] == []
