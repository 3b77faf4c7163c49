"""422s that name the mistake: what was expected, what came, and the likely fix, in the
service's own words (JSON's ``null``, never Python's ``None``; none of pydantic's phrases),
and the documented 409 for raw trials sent to a model of samples, before they are read."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.api.sample_input import explain, is_one_sample
from tests.service_fixtures import npy, problem, register

NPY = {"Content-Type": "application/x-npy"}
PYDANTIC = ("Input should", "List should", "String should", "after validation")

# a raw trial whose phases cannot be found (too short): what such a model would refuse
SHORT_FINGER = {
    "pdc": [1.0] * 100,
    "tdc": [1.0] * 100,
    "tac": [1.0] * 100,
    "pac": [[1.0] * 22] * 100,
    "electrodes": [[1.0] * 19] * 100,
}


def _squeezed(sample: list) -> list:
    """A (32, 30) simulated sample after the squeeze alone: the other procedures' rows null."""
    return sample[:8] + [None] * 24


def _in_own_words(body: dict) -> None:
    text = json.dumps(body)
    assert not any(p in text for p in PYDANTIC) and "None" not in text, body


def test_one_sample_alone_is_taken_in_json_as_in_npy(client, dataset, sample):
    """The same lone sample, without its list, gets the same answer either way."""
    by_json = client.post("/v1/recognize", json={"samples": sample})
    by_npy = client.post("/v1/recognize", content=npy(dataset.samples[0]), headers=NPY)
    assert by_json.status_code == by_npy.status_code == 200, by_json.text
    assert len(by_json.json()["results"]) == 1
    assert by_json.json() == by_npy.json()
    # with procedures missing (read as one sample: this method answers from all of them)
    partial = client.post("/v1/recognize", json={"samples": _squeezed(sample)})
    assert "sample 0 lacks hold, slide, move_down" in problem(partial, 422)["detail"]
    # and with a bad value, named where it was sent
    sample[2][5] = "x"
    found = problem(client.post("/v1/recognize", json={"samples": sample}), 422)
    assert found["errors"] == [{"field": "samples[2][5]", "reason": 'not a number (got "x")'}]


def test_registering_one_sample_alone_says_wrap_it_in_a_list(client, sample):
    r = client.post("/v1/classes", json={"name": "mug", "attributes": ["hard"], "samples": sample})
    found = problem(r, 422, "samples")
    assert found["detail"] == (
        "samples: expected a list of samples, got one sample of shape [32, 30] alone: "
        "wrap one sample in a list"
    )


def test_adding_a_sample_in_a_list_says_send_it_without_its_list(client, dataset, sample):
    cid = register(client, dataset, "mug")["class"]["id"]
    one = client.post(f"/v1/classes/{cid}/samples", json={"sample": [sample]})
    found = problem(one, 422, "sample")
    assert found["detail"] == (
        "sample: expected one sample of shape [32, 30], got a list holding one: send the "
        "sample without its outer list"
    )
    two = client.post(f"/v1/classes/{cid}/samples", json={"sample": [sample, sample]})
    assert "got a list of 2: send them one at a time" in problem(two, 422, "sample")["detail"]
    _in_own_words(found)


@pytest.mark.parametrize("body", ["json", "npy"])
def test_one_nan_cell_is_named_by_its_place(client, dataset, body):
    x = dataset.samples[:2].copy()
    x[1, 3, 4] = np.nan
    if body == "npy":
        r = client.post("/v1/recognize", content=npy(x), headers=NPY)
    else:
        raw = json.dumps({"samples": x.tolist()})  # NaN as JSON's NaN literal
        r = client.post("/v1/recognize", content=raw, headers={"content-type": "application/json"})
    detail = problem(r, 422, "samples")["detail"]
    assert "cell [1][3][4] is NaN" in detail and "procedure 'squeeze'" in detail


def test_a_nan_cell_in_an_enrolment_is_named_where_it_was_sent(client, dataset, sample):
    cid = register(client, dataset, "mug")["class"]["id"]
    sample[3][4] = "__NaN__"
    one = json.dumps({"sample": sample}).replace('"__NaN__"', "NaN")
    r = client.post(
        f"/v1/classes/{cid}/samples", content=one, headers={"content-type": "application/json"}
    )
    assert "cell sample[3][4] is NaN" in problem(r, 422, "sample")["detail"]
    two = {"name": "cup", "attributes": ["soft"], "samples": [dataset.samples[1].tolist(), sample]}
    raw = json.dumps(two).replace('"__NaN__"', "NaN")
    r = client.post("/v1/classes", content=raw, headers={"content-type": "application/json"})
    detail = problem(r, 422, "samples[1]")["detail"]
    assert detail.startswith(
        "samples[1]: procedure 'squeeze' is partly missing: cell samples[1][3][4]"
    )


def test_one_null_cell_is_named_as_json_names_it(client, sample):
    sample[3][4] = None
    found = problem(client.post("/v1/recognize", json={"samples": [sample]}), 422)
    assert found["errors"] == [{"field": "samples[0][3][4]", "reason": "not a number (got null)"}]
    assert "a procedure not done yet is null as whole rows" in found["detail"]
    _in_own_words(found)


def test_enrolment_takes_whole_samples_naming_the_missing_procedures(client, dataset, sample):
    cid = register(client, dataset, "mug")["class"]["id"]
    squeezed = _squeezed(sample)
    r = client.post(f"/v1/classes/{cid}/samples", json={"sample": squeezed})
    found = problem(r, 422, "sample")
    assert found["detail"].startswith(
        "sample: enrolment takes whole samples: procedures 'hold', 'slide' and 'move_down' "
        "are missing (null)"
    )
    _in_own_words(found)
    r = client.post(
        "/v1/classes",
        json={"name": "cup", "attributes": ["soft"], "samples": [sample, squeezed]},
    )
    found = problem(r, 422, "samples[1]")
    assert "enrolment takes whole samples: procedures 'hold', 'slide'" in found["detail"]
    # one entry per procedure, and NaN where JSON names it: the same rule
    per = [sample[:8], None, sample[16:24], None]
    r = client.post(f"/v1/classes/{cid}/samples", json={"sample": per})
    assert "procedures 'hold' and 'move_down' are missing" in problem(r, 422)["detail"]
    raw = json.dumps({"sample": sample[:8] + [[float("nan")] * 30] * 24})
    r = client.post(
        f"/v1/classes/{cid}/samples", content=raw, headers={"content-type": "application/json"}
    )
    detail = problem(r, 422, "sample")["detail"]
    assert "enrolment takes whole samples: procedures 'hold', 'slide' and 'move_down'" in detail


@pytest.mark.parametrize(
    ("method", "path", "kwargs", "expected"),
    [
        ("get", "/v1/jobs/1?wait=30", {}, 'wait: at most 20.0 (got "30")'),
        ("get", "/v1/classes?limit=0", {}, 'limit: at least 1 (got "0")'),
        ("post", "/v1/recognize", {"json": {"samples": []}}, "samples: at least 1 item needed"),
        (
            "post",
            "/v1/classes",
            {"json": {"name": "", "attributes": ["hard"]}},
            'name: at least 1 character needed (got "")',
        ),
        (
            "post",
            "/v1/classes",
            {"json": {"name": "a\tb", "attributes": ["hard"]}},
            "name: a control character is not allowed here",
        ),
        (
            "post",
            "/v1/attributes",
            {"json": {"name": "sticky,wet"}},
            "name: a control character or a comma is not allowed here",
        ),
    ],
)
def test_constraints_are_named_in_the_services_words(client, method, path, kwargs, expected):
    r = getattr(client, method)(path, **kwargs)
    found = problem(r, 422)
    assert found["detail"].startswith(expected), found
    _in_own_words(found)


def test_a_reason_does_not_repeat_its_field(client, sample):
    r = client.post("/v1/recognize?target_confidence=2", json={"samples": [sample]})
    found = problem(r, 422, "target_confidence")
    assert found["detail"] == "target_confidence: a probability in (0, 1] is needed (got '2')"
    assert found["errors"] == [
        {"field": "target_confidence", "reason": "a probability in (0, 1] is needed (got '2')"}
    ]


def test_a_raw_trial_for_a_model_of_samples_is_the_documented_409(client, dataset):
    """Said before the trial is read: its phases, which cannot be found here, do not matter."""
    trial = {"fingers": [SHORT_FINGER]}
    cid = register(client, dataset, "mug")["class"]["id"]
    answers = [
        (client.post("/v1/recognize", json={"trials": [trial]}), "trials"),
        (client.post("/v1/describe", json={"trials": [trial]}), "trials"),
        (
            client.post(
                "/v1/recognize", content=b"not hdf5", headers={"Content-Type": "application/x-hdf5"}
            ),
            "trials",
        ),
        (client.post(f"/v1/classes/{cid}/samples", json={"trial": trial}), "trial"),
        (client.post("/v1/classes", json={"name": "cup", "trials": [trial]}), "trials"),
    ]
    for r, field in answers:
        found = problem(r, 409, field)
        assert found["detail"].startswith(
            "this model takes samples of shape [32, 30] (`input_kind` `samples` of "
            'GET /v1/models/active), not raw BioTac trials: send {"samples": [...]}'
        ), found


def test_a_flat_sample_is_told_apart_from_a_list_of_them():
    """PHAC-2's layout (a flat vector, procedures as slices): the same rules by shape."""
    shape, procedures = (8,), ("squeeze", "hold")
    flat, per = [0.1] * 8, [[0.1] * 4, None]
    assert is_one_sample(flat, shape, procedures) and is_one_sample(per, shape, procedures)
    assert not is_one_sample([flat], shape, procedures)
    assert not is_one_sample([per, flat], shape, procedures)
    squeezed = [0.1] * 4 + [None] * 4
    assert explain({"sample": squeezed}, shape, procedures, partial=False) == [
        {
            "field": "sample",
            "reason": "enrolment takes whole samples: procedure 'hold' is missing (null); send "
            "the sample once every procedure is done (POST /v1/recognize answers from some)",
        }
    ]
    (wrap,) = explain({"samples": flat}, shape, procedures, partial=False)
    assert wrap["reason"].endswith("wrap one sample in a list")
    assert explain({"samples": flat}, shape, procedures, partial=True) == []  # taken alone
