"""The paper's pipeline learns an added attribute by a full fit (G takes the vocabulary as
its input, so its input layer grows), with the classes not known for it given the prior;
a retired attribute leaves the next model (the ``best`` side: tests/api/test_api_attributes)."""

from __future__ import annotations

import numpy as np

from tests.service_fixtures import job, register


def served(app):
    return app.state.service.holder.current.recognizer


def first_layer_inputs(model) -> int:
    """What G's first layer takes: one input per attribute (channels of a deconvolution)."""
    return next(p for p in model.generator_.parameters() if p.ndim > 1).shape[0]


def test_the_paper_pipeline_is_fitted_again_with_a_wider_generator(client, app, worker, dataset):
    before = served(app)
    m = len(before.registry.attribute_names)
    assert first_layer_inputs(before) == m
    mug = register(client, dataset, "mug", 0)["class"]["name"]
    values = {dataset.class_names[0]: 1, dataset.class_names[1]: 0.5, mug: 1}
    r = client.post("/v1/attributes", json={"name": "sticky", "values": values})
    assert r.status_code == 202, r.text
    worker.run_once()
    assert job(client, r.json()["job"]["id"])["status"] == "succeeded"
    model = served(app)
    reg = model.registry
    assert reg.attribute_names[-1] == "sticky" and first_layer_inputs(model) == m + 1
    sticky = reg.known_attributes[:, -1]
    assert sticky[0] == 1 and sticky[1] == 0.5 and np.isnan(sticky[2:]).all()
    assert reg.novel_attributes[reg.novel_names.index("mug"), -1] == 1
    assert client.get("/v1/models/active").json()["reason"] == "update"

    r = client.delete("/v1/attributes/sticky")
    assert r.status_code == 202, r.text
    worker.run_once()
    assert job(client, r.json()["job"]["id"])["status"] == "succeeded"
    assert served(app).registry.attribute_names == before.registry.attribute_names
