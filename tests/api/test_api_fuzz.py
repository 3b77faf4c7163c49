"""A bounded run of bench/fuzz.py's harness on each store: schemathesis on the service's own
OpenAPI document with a key of each scope, every operation on its own and stateful scenarios
along the document's links. No 5xx; every status code, content type and promised header
documented; every body (2xx and problems) matching its schema; every 4xx problem+json; 401
without a key and 403 exactly where the key's scope is too small. (The benchmark size is
``python -m bench.fuzz``.)"""

from __future__ import annotations

from bench.fuzz import NEEDS, SCOPES, expected_auth, fuzz

EXAMPLES_PER_OPERATION = 12
SCENARIOS, STEPS = 40, 10
SECONDS = 45  # per store, whatever the machine: the run stops sending after it


def test_the_scope_table_covers_every_operation_of_the_document(client):
    doc = client.get("/openapi.json").json()
    labels = {f"{m.upper()} {p}" for p, ops in doc["paths"].items() for m in ops}
    assert labels == set(NEEDS)
    for label, needs in NEEDS.items():  # the document marks the key on exactly the /v1 ones
        method, path = label.split(" ", 1)
        assert ("security" in doc["paths"][path][method.lower()]) == (needs is not None), label
    assert expected_auth("GET /v1/classes", None) == 401
    assert expected_auth("POST /v1/classes", "read") == 403
    assert expected_auth("POST /v1/classes", "enroll") is None
    assert expected_auth("POST /v1/attributes", "enroll") == 403
    assert expected_auth("POST /v1/models/{version}/activate", "admin") is None
    assert expected_auth("GET /healthz", None) is None
    assert SCOPES == ("read", "enroll", "admin")


def test_the_document_links_a_class_to_its_samples_and_a_sample_to_recognition(client):
    doc = client.get("/openapi.json").json()
    ids = {op["operationId"] for ops in doc["paths"].values() for op in ops.values()}

    def links(path: str, method: str, status: str) -> dict:
        return doc["paths"][path][method]["responses"][status]["links"]

    registered = links("/v1/classes", "post", "202")
    assert registered["AddSample"]["parameters"] == {"class_id": "$response.body#/class/id"}
    assert registered["WithdrawClass"]["operationId"] == "classes-withdraw_class"
    added = links("/v1/classes/{class_id}/samples", "post", "202")
    assert added["GetSample"]["parameters"]["sample_id"] == "$response.body#/sample_id"
    stored = links("/v1/classes/{class_id}/samples/{sample_id}", "get", "200")
    assert stored["Recognize"]["requestBody"] == {"samples": ["$response.body#/sample"]}
    attribute = links("/v1/attributes", "post", "202")
    assert attribute["RegisterClass"]["requestBody"]["attributes"] == {
        "$response.body#/attribute/name": 1
    }
    assert attribute["RetireAttribute"]["operationId"] == "attributes-retire_attribute"
    every = [
        link
        for ops in doc["paths"].values()
        for op in ops.values()
        for response in op["responses"].values()
        for link in response.get("links", {}).values()
    ]
    assert len(every) >= 30 and {link["operationId"] for link in every} <= ids
    headers = doc["paths"]["/v1/classes"]["post"]["responses"]["202"]["headers"]
    assert headers["Location"]["required"] is True


def test_fuzzing_with_keys_finds_nothing_the_document_does_not_say(app, client, dataset):
    fuzzer = fuzz(app, dataset, EXAMPLES_PER_OPERATION, SCENARIOS, STEPS, SECONDS)
    report = fuzzer.report("", 0)
    assert fuzzer.failures == [], report
    assert report["5xx"] == 0 and report["violations"] == {}
    assert report["operations"] == len(NEEDS)  # every operation was exercised
    statuses = report["statuses"]
    # the keys were used: each refusal came, and so did answers
    assert statuses.get("401", 0) > 0 and statuses.get("403", 0) > 0
    assert statuses.get("200", 0) > 0 and statuses.get("202", 0) > 0
    assert fuzzer.scenarios > 0 and fuzzer.links_followed  # the links were followed
