"""POST /v1/recognize with samples that lack procedures: null rows or NaN, each answer's
procedures_used and next_procedure, target_confidence; the model names its procedures."""

from __future__ import annotations

import numpy as np

from app.client import TactileClient
from app.data.procedures import keep_only
from app.framework.recognizer import MIN_PROCEDURES
from tests.service_fixtures import npy, problem

PROCEDURES = ["squeeze", "hold", "slide", "move_down"]


def _squeezed(sample: np.ndarray) -> list:
    """A (32, 30) simulated sample after the squeeze alone, as JSON rows (null elsewhere)."""
    rows = sample.tolist()
    return rows[:8] + [None] * 24


def test_the_served_model_names_its_procedures_and_the_first(best_service):
    client, _, _ = best_service
    active = client.get("/v1/models/active").json()
    assert active["procedures"] == PROCEDURES
    assert active["first_procedure"] in PROCEDURES
    listed = client.get("/v1/models").json()["models"][0]
    assert listed["procedures"] == PROCEDURES
    # which rows of a (32, 30) sample each procedure takes: 4 blocks of 8
    rows = {"squeeze": [0, 8], "hold": [8, 16], "slide": [16, 24], "move_down": [24, 32]}
    assert active["procedure_rows"] == rows and listed["procedure_rows"] == rows


def test_procedure_rows_say_which_rows_a_missing_procedure_leaves_null(best_service, best_base):
    """A sample built from procedure_rows alone (squeeze and slide done) is answered from
    exactly those procedures; /docs shows the field with its example."""
    client, _, _ = best_service
    x = best_base[1].samples[0].tolist()
    spans = client.get("/v1/models/active").json()["procedure_rows"]
    done = ("squeeze", "slide")
    sample = [None] * len(x)
    for name in done:
        start, stop = spans[name]
        sample[start:stop] = x[start:stop]
    answer = client.post("/v1/recognize", json={"samples": [sample]}).json()["results"][0]
    assert answer["procedures_used"] == list(done)
    schema = client.get("/openapi.json").json()["components"]["schemas"]
    field = schema["ModelOut"]["properties"]["procedure_rows"]
    assert "[start, stop)" in field["description"] and field["examples"][0]["hold"] == [8, 16]
    assert None in schema["RecognizeRequest"]["properties"]["samples"]["examples"][0][1]


def test_a_sample_with_null_rows_is_answered_from_the_procedures_it_holds(best_service, best_base):
    client, _, _ = best_service
    _, dataset = best_base
    x = dataset.samples[0]
    r = client.post("/v1/recognize", json={"samples": [_squeezed(x), x.tolist()]})
    assert r.status_code == 200, r.text
    first, whole = r.json()["results"]
    assert first["procedures_used"] == ["squeeze"]
    assert whole["procedures_used"] == PROCEDURES and whole["next_procedure"] is None
    # the same sample as one entry per procedure: (4, 8, 30) with null entries
    per = [x[:8].tolist(), None, None, None]
    again = client.post("/v1/recognize", json={"samples": [per]}).json()["results"][0]
    assert again == first


def _unsure(best_base) -> np.ndarray:
    """A sample unlike the training ones (which the forest answers with probability 1)
    whose answer after the squeeze alone has a probability below 1."""
    model, dataset = best_base
    rng = np.random.default_rng(0)
    noisy = dataset.samples + rng.normal(0, dataset.samples.std(), dataset.samples.shape)
    squeezed = keep_only(noisy.astype(np.float32), dataset.procedures, [0])
    p = model.recognize_batch(squeezed, top_k=1).top_probability[:, 0]
    assert p.min() < 1
    return noisy[int(np.argmin(p))].astype(np.float32)


def test_next_procedure_follows_the_target_confidence(best_service, best_base):
    client, _, _ = best_service
    x = _unsure(best_base)
    body = {"samples": [_squeezed(x)]}
    unsure = client.post("/v1/recognize?target_confidence=1", json=body).json()["results"][0]
    assert unsure["next_procedure"] in PROCEDURES[1:]
    # sure, but after one procedure: a second one first
    one = client.post("/v1/recognize?target_confidence=0.0001", json=body).json()["results"][0]
    assert one["next_procedure"] in PROCEDURES[1:]
    two = x.tolist()[:8] + [None] * 16 + x.tolist()[24:]  # squeeze and move down
    body_two = {"samples": [two]}
    sure = client.post("/v1/recognize?target_confidence=0.0001", json=body_two).json()
    assert sure["results"][0]["next_procedure"] is None
    assert sure["results"][0]["procedures_used"] == ["squeeze", "move_down"]
    problem(client.post("/v1/recognize?target_confidence=2", json=body), 422, "target_confidence")
    problem(client.post("/v1/recognize?target_confidence=x", json=body), 422, "target_confidence")


def test_nan_in_a_npy_body_is_a_missing_procedure(best_service, best_base):
    client, _, _ = best_service
    x = best_base[1].samples[:2].copy()
    x[:, 8:] = np.nan
    r = client.post("/v1/recognize", content=npy(x), headers={"Content-Type": "application/x-npy"})
    assert r.status_code == 200, r.text
    assert [a["procedures_used"] for a in r.json()["results"]] == [["squeeze"]] * 2


def test_a_partly_missing_procedure_or_none_is_a_422_that_says_which(best_service, best_base):
    client, _, _ = best_service
    rows = best_base[1].samples[0].tolist()
    rows[10] = None  # one of hold's eight rows
    body = problem(client.post("/v1/recognize", json={"samples": [rows]}), 422, "samples")
    assert "procedure 'hold' is partly missing: cell [0][10][0] is NaN" in body["detail"]
    body = problem(client.post("/v1/recognize", json={"samples": [[None] * 32]}), 422)
    assert "every procedure is missing" in body["detail"]
    # enrolment needs every procedure
    cls = client.get("/v1/classes", params={"limit": 1}).json()["classes"][0]
    r = client.post(
        f"/v1/classes/{cls['id']}/samples", json={"sample": _squeezed(np.zeros((32, 30)))}
    )
    found = problem(r, 422, "sample")
    assert found["detail"].startswith(
        "sample: enrolment takes whole samples: procedures 'hold', 'slide' and 'move_down' are "
        "missing (null)"
    )


def test_same_object_fuses_touches_of_different_procedures(best_service, best_base):
    client, _, _ = best_service
    x = best_base[1].samples[0]
    slide = [None] * 16 + x[16:24].tolist() + [None] * 8
    r = client.post("/v1/recognize?same_object=true", json={"samples": [_squeezed(x), slide]})
    assert r.status_code == 200, r.text
    (answer,) = r.json()["results"]
    assert answer["procedures_used"] == ["squeeze", "slide"]


def test_the_client_explores_procedure_by_procedure(best_service, best_base):
    client, _, _ = best_service
    x = _unsure(best_base)
    asked: list[str] = []

    def touch(name: str) -> np.ndarray:
        asked.append(name)
        j = PROCEDURES.index(name)
        return x[j * 8 : (j + 1) * 8]

    tactile = TactileClient("http://testserver", http=client)
    answer = tactile.explore(touch, target_confidence=1.0)  # never sure: every procedure
    assert answer["procedures_done"] == asked and sorted(asked) == sorted(PROCEDURES)
    assert asked[0] == client.get("/v1/models/active").json()["first_procedure"]
    assert answer["next_procedure"] is None and answer["procedures_used"] == PROCEDURES
    quick = tactile.explore(touch, target_confidence=1e-6)
    assert len(quick["procedures_done"]) == MIN_PROCEDURES  # sure at once
