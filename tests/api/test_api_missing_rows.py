"""A procedure not done is a missing row in every encoding a client writes: whole-row
``null``, rows of ``null`` cells (orjson and JavaScript's ``JSON.stringify`` write NaN as
``null``) and rows of NaN (Python's ``json``), on every route that takes samples."""

from __future__ import annotations

import json

from tests.service_fixtures import problem, register

NAN = "__NaN__"
DONE = ("squeeze",)


def _post(client, path: str, body: dict):
    """``body`` as JSON, with ``NAN`` written as the literal NaN, as Python's json does."""
    raw = json.dumps(body).replace(f'"{NAN}"', "NaN")
    return client.post(path, content=raw, headers={"content-type": "application/json"})


def _squeezed(x: list, missing) -> list:
    """``x`` (32 rows of 30) after the squeeze alone, each other row ``missing``."""
    return x[:8] + [missing] * 24


def _encodings(x: list) -> dict[str, list]:
    return {
        "null cells": _squeezed(x, [None] * 30),
        "NaN cells": _squeezed(x, [NAN] * 30),
        "null and NaN cells": _squeezed(x, [None, NAN] * 15),
        "per procedure, null cells": [x[:8], [[None] * 30] * 8, None, [[NAN] * 30] * 8],
    }


def test_rows_without_a_number_are_a_missing_procedure_when_recognising(best_service, best_base):
    client, _, _ = best_service
    sample = best_base[1].samples[0].tolist()
    for path in ("/v1/recognize", "/v1/describe"):
        r = _post(client, path, {"samples": [_squeezed(sample, None)]})
        assert r.status_code == 200, r.text
        expected = r.json()["results"]
        if path == "/v1/recognize":
            assert expected[0]["procedures_used"] == list(DONE)
        for name, s in _encodings(sample).items():
            r = _post(client, path, {"samples": [s]})
            assert r.status_code == 200, (path, name, r.text)
            assert r.json()["results"] == expected, (path, name)
            alone = _post(client, path, {"samples": s})  # one sample without its list
            assert alone.status_code == 200 and alone.json()["results"] == expected, (path, name)


def test_a_row_with_some_null_cells_is_a_422_that_names_it(best_service, best_base):
    client, _, _ = best_service
    sample = best_base[1].samples[0].tolist()
    s = _squeezed(sample, None)
    s[9] = [None] * 15 + [0.5] * 15
    found = problem(_post(client, "/v1/recognize", {"samples": [s]}), 422)
    assert found["errors"][0]["field"] == "samples[0][9][0]", found
    assert "or rows of null or NaN cells; a row with some numbers needs all" in found["detail"]
    every = problem(_post(client, "/v1/recognize", {"samples": [[[None] * 30] * 32]}), 422)
    assert "every procedure is missing" in every["detail"]


def test_enrolment_names_the_procedures_rows_of_null_cells_leave_out(client, dataset, sample):
    cid = register(client, dataset, "mug")["class"]["id"]
    squeezed = _squeezed(sample, [None] * 30)
    missing = "procedures 'hold', 'slide' and 'move_down' are missing (null)"
    r = _post(client, f"/v1/classes/{cid}/samples", {"sample": squeezed})
    found = problem(r, 422, "sample")
    assert found["detail"].startswith(f"sample: enrolment takes whole samples: {missing}")
    body = {"name": "cup", "attributes": ["soft"], "samples": [sample, squeezed]}
    found = problem(_post(client, "/v1/classes", body), 422, "samples[1]")
    assert found["detail"].startswith(f"samples[1]: enrolment takes whole samples: {missing}")
    nan = _squeezed(sample, [NAN] * 30)
    found = problem(_post(client, f"/v1/classes/{cid}/samples", {"sample": nan}), 422, "sample")
    assert "'hold', 'slide' and 'move_down'" in found["detail"] and "missing" in found["detail"]
