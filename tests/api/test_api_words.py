"""Objects described in words over HTTP: POST /v1/attributes/interpret, classes registered
and corrected with a description, a word added to the vocabulary read from the texts, bad
text refused with nothing stored. The real sentence-embedding model and a ``best`` service
on each store; the worker learns a class described in words."""

from __future__ import annotations

import pytest

from tests.service_fixtures import problem

SPONGE = "a soft, spongy foam block that soaks up water"


@pytest.fixture
def service(best_stores_service):
    return best_stores_service


def classes(client) -> list[dict]:
    return client.get("/v1/classes", params={"limit": 1000}).json()["classes"]


def test_interpret_reads_graded_negated_and_paraphrased_values(service):
    client, _, _ = service
    r = client.post("/v1/attributes/interpret", json={"text": SPONGE})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["values"]["soft"] == pytest.approx(0.9)
    assert body["values"]["absorbent"] == pytest.approx(0.9)  # "soaks up water"
    assert "metallic" not in body["values"] and "metallic" in body["not_mentioned"]
    assert {x["attribute"]: x["words"] for x in body["readings"]}["absorbent"] in SPONGE
    r = client.post("/v1/attributes/interpret", json={"text": "not hard, slightly rough"})
    assert r.json()["values"]["hard"] == 0.0 and r.json()["values"]["rough"] == 0.6


@pytest.mark.parametrize(
    ("text", "reason"),
    [("", "empty"), ("  \t", "empty"), ("soft " * 300, "at most 1000"), ("a blue gift", "closest")],
)
def test_bad_text_is_a_422_that_says_why(service, text, reason):
    client, _, _ = service
    r = client.post("/v1/attributes/interpret", json={"text": text})
    assert reason in problem(r, 422, "text")["detail"]
    before = len(classes(client))
    r = client.post("/v1/classes", json={"name": "x", "description": text})
    assert reason in problem(r, 422, "description")["detail"]
    assert len(classes(client)) == before  # nothing stored


def test_a_class_registered_in_words_keeps_its_text_and_is_learnt(service):
    client, _, worker = service
    r = client.post("/v1/classes", json={"name": "foam block", "description": SPONGE})
    assert r.status_code == 202, r.text
    cid = r.json()["class"]["id"]
    worker.run_once()
    cls = client.get(f"/v1/classes/{cid}").json()
    assert cls["description"] == SPONGE and cls["in_active_model"] is True
    read = {x["attribute"]: x for x in cls["description_readings"]}
    assert cls["attribute_values"]["soft"] == read["soft"]["value"] == pytest.approx(0.9)
    # not mentioned: estimated from what the text says, and shown as an estimate
    assert read["metallic"]["source"] == "estimated" and read["soft"]["source"] == "word"
    assert cls["attribute_values"]["metallic"] == read["metallic"]["value"] < 0.5
    assert "soft" in read["metallic"]["words"]
    # a name alone is a description too
    r = client.post("/v1/classes", json={"name": "vase", "description": "steel vase"})
    assert r.status_code == 202 and r.json()["class"]["attribute_values"]["metallic"] >= 0.5


def test_values_beside_a_text_must_agree_with_it(service):
    client, _, _ = service
    before = len(classes(client))
    r = client.post(
        "/v1/classes",
        json={"name": "odd", "description": "very hard and smooth", "attributes": {"hard": 0}},
    )
    assert "very hard" in problem(r, 422, "attributes")["detail"]
    assert len(classes(client)) == before
    r = client.post(
        "/v1/classes",
        json={"name": "ok", "description": "very hard and smooth", "attributes": {"cool": 1}},
    )
    assert r.status_code == 202, r.text
    values = r.json()["class"]["attribute_values"]
    said = {"hard": 1.0, "soft": 0.0, "smooth": 0.9, "rough": 0.1, "cool": 1.0}
    assert {a: values[a] for a in said} == pytest.approx(said)
    r = client.post(  # a value given overrides an estimate, where it would a value read
        "/v1/classes",
        json={"name": "ok2", "description": "very hard and rough", "attributes": {"cool": 0}},
    )
    assert r.status_code == 202, r.text
    readings = {x["attribute"]: x for x in r.json()["class"]["description_readings"]}
    assert readings["cool"]["source"] == "estimated"
    assert r.json()["class"]["attribute_values"]["cool"] == 0.0


def test_patch_replaces_the_text_and_a_new_word_is_read_from_texts(service):
    client, _, worker = service
    cid = client.post("/v1/classes", json={"name": "ball", "description": "a soft ball"}).json()[
        "class"
    ]["id"]
    other = client.post("/v1/classes", json={"name": "cube", "attributes": {"hard": 1}}).json()
    r = client.patch(f"/v1/classes/{cid}", json={"description": "a soft rubbery ball"})
    assert r.status_code == 202, r.text
    assert r.json()["class"]["description"] == "a soft rubbery ball"
    r = client.post("/v1/attributes", json={"name": "rubbery"})
    assert r.status_code == 202, r.text
    worker.run_once()
    ball = client.get(f"/v1/classes/{cid}").json()
    assert ball["attribute_values"]["rubbery"] == pytest.approx(0.9)
    assert any(x["attribute"] == "rubbery" for x in ball["description_readings"])
    cube = client.get(f"/v1/classes/{other['class']['id']}").json()
    assert "rubbery" not in cube["attribute_values"]  # no text: not known
    jobs = client.get("/v1/jobs", params={"limit": 100}).json()["jobs"]
    assert {j["status"] for j in jobs} == {"succeeded"}, jobs


def test_an_empty_or_unknown_attribute_is_a_422_that_names_the_field_and_the_way_to_add_one(
    service,
):
    client, _, _ = service
    before = len(classes(client))
    r = client.post("/v1/classes", json={"name": "x", "attributes": []})
    detail = problem(r, 422, "attributes")["detail"]
    assert detail.startswith("attributes gives no attribute a value above 0"), detail
    assert "description" not in detail
    r = client.post("/v1/classes", json={"name": "x", "attributes": ["sticky"]})
    detail = problem(r, 422, "attributes")["detail"]
    assert "'sticky' (did you mean 'thick'?)" in detail
    assert detail.endswith("a new one can be added with POST /v1/attributes"), detail
    for path, body, field in [
        ("/v1/classes", {"name": "x", "description": "a blue gift"}, "description"),
        ("/v1/attributes/interpret", {"text": "a blue gift"}, "text"),
    ]:
        detail = problem(client.post(path, json=body), 422, field)["detail"]
        assert "the closest are" in detail
        assert "can be added with POST /v1/attributes" in detail, detail
    assert len(classes(client)) == before  # nothing stored
