"""POST /v1/recognize with ``objects``: a table of objects named jointly over HTTP, as
``app.framework.tables.name_table`` names it in process, for JSON, .npy (labels in the
query or a header), partial samples and raw trials; and every way the labels can be wrong,
each a 422 that names the fix."""

from __future__ import annotations

import numpy as np
import pytest

from app.api.schemas import RecognizeResponse
from app.data.biotac import write_biotac_h5
from app.data.procedures import block
from app.framework.tables import UNREGISTERED, name_table
from app.service.table_answers import LabelError, check_labels
from tests.api import test_api_raw_trials as raw
from tests.service_fixtures import npy, problem

NPY = {"content-type": "application/x-npy"}
# the real BioTac pilot model and its service, as the raw-trial tests fit them
pilot, raw_service, trial_json = raw.pilot, raw.raw_service, raw.trial_json


def served(app):
    """(the served recognizer, the operating point the service answers at by default)."""
    state = app.state.service
    rec = state.holder.current.recognizer
    return rec, rec.operating_point(None, state.recognition.known_kept)


def table_of(dataset, per_object: int, classes=range(4)) -> np.ndarray:
    """``per_object`` samples of each of ``classes``, object after object."""
    return np.concatenate([dataset.samples[dataset.labels == k][:per_object] for k in classes])


def expected(rec, x, objects, known_kept, class_ids) -> list[dict]:
    """What name_table says of the table, in the route's words."""
    answers, columns = name_table(rec, x, objects, known_kept=known_kept)

    def named(column: int) -> dict:
        name = columns[column]
        if name is UNREGISTERED:
            return {"class_id": None, "class_name": None, "kind": "novel"}
        kind = "known" if name in rec.registry.known_names else "novel"
        return {"class_id": class_ids[name], "class_name": name, "kind": kind}

    return [
        {
            "object": a.object,
            **named(a.column),
            "alone": named(a.alone),
            "margin": a.margin,
            "touches": len(a.rows),
        }
        for a in answers
    ]


def picked(results: list[dict]) -> list[dict]:
    keys = ("object", "class_id", "class_name", "kind", "alone", "margin", "touches")
    return [{k: r[k] for k in keys} for r in results]


def assert_same_table(got: list[dict], want: list[dict]) -> None:
    assert [{**r, "margin": None} for r in picked(got)] == [{**r, "margin": None} for r in want]
    np.testing.assert_allclose([r["margin"] for r in got], [r["margin"] for r in want], rtol=1e-9)


def test_http_answers_are_name_tables_and_fuse_each_objects_touches(best_service, best_base):
    client, app, _ = best_service
    rec, kept = served(app)
    class_ids = app.state.service.holder.current.class_ids
    x = table_of(best_base[1], 3)
    objects = ["cup", 7, "cup", "box", 7, 7, "box", "cup", "lid", "lid", "box", "lid"]
    r = client.post("/v1/recognize", json={"samples": x.tolist(), "objects": objects})
    assert r.status_code == 200, r.text
    body = r.json()
    RecognizeResponse.model_validate(body)
    results = body["results"]
    assert [a["object"] for a in results] == ["cup", 7, "box", "lid"]  # first appearance
    assert_same_table(results, expected(rec, x, objects, kept, class_ids))
    # each object's other fields are its touches fused, as same_object answers them
    for result in results:
        rows = [i for i, o in enumerate(objects) if o == result["object"]]
        (fused,) = client.post(
            "/v1/recognize?same_object=true", json={"samples": x[rows].tolist()}
        ).json()["results"]
        assert result["touches"] == len(rows) == 3
        for field in ("novelty_score", "is_novel", "top_k", "procedures_used", "known_kept"):
            assert result[field] == fused[field], field
    # an ordinary answer carries none of the table's fields
    (one,) = client.post("/v1/recognize", json={"samples": x[:1].tolist()}).json()["results"]
    assert not {"object", "alone", "margin", "touches"} & set(one)


def test_no_class_goes_to_two_objects_but_novel_may_repeat(best_service, best_base):
    client, app, _ = best_service
    data = best_base[1]
    # two distinct objects of each of 6 known classes: each class can name one of them
    x = np.concatenate([data.samples[data.labels == k][:2] for k in range(6)])
    objects = [f"object {i}" for i in range(len(x))]
    r = client.post("/v1/recognize", json={"samples": x.tolist(), "objects": objects})
    results = r.json()["results"]
    named = [a["class_name"] for a in results if a["class_name"] is not None]
    assert len(named) == len(set(named)) >= 1
    unregistered = [a for a in results if a["class_name"] is None]
    assert len(unregistered) >= 2 and all(a["kind"] == "novel" for a in unregistered)
    # alone, the two touches of a class are both called it: the table gave way
    alone = [a["alone"]["class_name"] for a in results]
    assert any(alone.count(n) == 2 for n in named)
    assert all(a["margin"] >= 0 for a in results)
    rec, kept = served(app)
    class_ids = app.state.service.holder.current.class_ids
    assert_same_table(results, expected(rec, x, objects, kept, class_ids))


def test_npy_bodies_take_labels_from_the_query_or_the_header(best_service, best_base):
    client, app, _ = best_service
    x = table_of(best_base[1], 2)
    labels = ["a", "b", "b", "c", "a", "c", "d", "d"]
    by_json = client.post("/v1/recognize", json={"samples": x.tolist(), "objects": labels})
    by_query = client.post(
        "/v1/recognize", content=npy(x), headers=NPY, params={"objects": ",".join(labels)}
    )
    by_header = client.post(
        "/v1/recognize",
        content=npy(x),
        headers={**NPY, "X-Tactile-Objects": " , ".join(labels)},  # spaces are dropped
    )
    both = client.post(
        "/v1/recognize",
        content=npy(x),
        headers={**NPY, "X-Tactile-Objects": ",".join(labels)},
        params={"objects": ",".join(labels)},
    )
    assert by_json.status_code == by_query.status_code == by_header.status_code == 200
    assert by_query.content == by_header.content == both.content
    assert by_query.json() == by_json.json()
    # the JSON body's labels and the query's may both be given when they agree
    agree = client.post(
        "/v1/recognize",
        json={"samples": x.tolist(), "objects": labels},
        params={"objects": ",".join(labels)},
    )
    assert agree.json() == by_json.json()


def test_partial_samples_known_kept_and_min_model_version(best_service, best_base):
    client, app, _ = best_service
    rec, _ = served(app)
    x = table_of(best_base[1], 2).copy()
    last = block(rec.procedures, rec.input_shape, len(rec.procedures) - 1)
    x[::2, last] = np.nan  # half the touches lack the last procedure
    objects = [0, 0, 1, 1, 2, 2, 3, 3]
    r = client.post(
        "/v1/recognize",
        json={"samples": np.where(np.isnan(x), None, x).tolist(), "objects": objects},
        params={"known_kept": 0.8, "min_model_version": 1},
    )
    assert r.status_code == 200, r.text
    results = r.json()["results"]
    assert all(a["known_kept"] == 0.8 for a in results)
    assert all(a["procedures_used"] == list(rec.procedures) for a in results)  # one complete
    class_ids = app.state.service.holder.current.class_ids
    assert_same_table(results, expected(rec, x, objects, 0.8, class_ids))
    problem(
        client.post(
            "/v1/recognize?min_model_version=9", json={"samples": x[1:2].tolist(), "objects": [1]}
        ),
        409,
        "min_model_version",
    )


def test_an_object_touched_once_per_procedure_is_answered_from_all_of_them(best_service, best_base):
    client, app, _ = best_service
    rec, kept = served(app)
    data = best_base[1]
    sample = data.samples[data.labels == 1][0]
    parts = np.full((len(rec.procedures), *sample.shape), np.nan, np.float32)
    for j in range(len(rec.procedures)):
        rows = block(rec.procedures, rec.input_shape, j)
        parts[j, rows] = sample[rows]  # one procedure a touch
    r = client.post(
        "/v1/recognize",
        json={"samples": np.where(np.isnan(parts), None, parts).tolist(), "objects": ["o"] * 4},
    )
    assert r.status_code == 200, r.text
    (result,) = r.json()["results"]
    assert result["touches"] == 4 and result["procedures_used"] == list(rec.procedures)
    class_ids = app.state.service.holder.current.class_ids
    assert_same_table([result], expected(rec, parts, ["o"] * 4, kept, class_ids))


BAD_LABELS = [
    # (labels in the body, a phrase of the detail, the field)
    ([], "no labels given; give one label per sample (3 samples)", "objects"),
    (["a", "b"], "2 labels for 3 samples", "objects"),
    (["a", "b", "c", "d"], "4 labels for 3 samples", "objects"),
    (["a", 1.5, "c"], "a string or an integer naming the object", "objects[1]"),
    (["a", None, "c"], "got null", "objects[1]"),
    (["a", "b", True], "got true or false", "objects[2]"),
    (
        ["a", {"id": 1}, "c"],
        "a string or an integer naming the object, got an object",
        "objects[1]",
    ),
    (["a", "", "c"], "the label is empty", "objects[1]"),
    (["a", "b", "   "], "the label is empty", "objects[2]"),
    (["a", 2**70, "c"], "got the number 1.1805916207174113e+21", "objects[1]"),
    (["a", "x" * 201, "c"], "at most 200 characters", "objects[1]"),
    ("a,b,c", "expected a list of labels", "objects"),
]


@pytest.mark.parametrize("labels, said, field", BAD_LABELS)
def test_bad_labels_in_a_json_body_are_a_422_naming_the_fix(
    best_service, best_base, labels, said, field
):
    client, app, _ = best_service
    x = table_of(best_base[1], 1, range(3))
    body = problem(
        client.post("/v1/recognize", json={"samples": x.tolist(), "objects": labels}), 422, field
    )
    assert said in body["detail"], body["detail"]


@pytest.mark.parametrize(
    "query, said, field",
    [
        ({"objects": ""}, "no labels given", "objects"),
        ({"objects": "a,,b"}, "the label is empty", "objects[1]"),
        ({"objects": "a,b"}, "2 labels for 3 samples", "objects"),
        ({"objects": "a,b,c", "same_object": "true"}, "use one or the other", "objects"),
    ],
)
def test_bad_query_labels_are_a_422_naming_the_fix(best_service, best_base, query, said, field):
    client, app, _ = best_service
    x = table_of(best_base[1], 1, range(3))
    body = problem(client.post("/v1/recognize", content=npy(x), headers=NPY, params=query), 422)
    assert said in body["detail"] and field in [e["field"] for e in body["errors"]], body


def test_labels_given_twice_must_agree_and_not_with_same_object(best_service, best_base):
    client, app, _ = best_service
    x = table_of(best_base[1], 1, range(3)).tolist()
    body = problem(
        client.post(
            "/v1/recognize?same_object=true", json={"samples": x, "objects": ["a", "b", "a"]}
        ),
        422,
        "objects",
    )
    assert "same_object" in body["detail"] and "one or the other" in body["detail"]
    body = problem(
        client.post(
            "/v1/recognize?objects=a,b,c",
            json={"samples": x, "objects": ["a", "b", "a"]},
        ),
        422,
        "objects",
    )
    assert "differ" in body["detail"] and "once" in body["detail"]
    body = problem(
        client.post(
            "/v1/recognize?objects=a,b,c",
            content=npy(np.asarray(x, np.float32)),
            headers={**NPY, "X-Tactile-Objects": "a,b,a"},
        ),
        422,
        "objects",
    )
    assert "X-Tactile-Objects" in body["detail"]
    # the samples' own errors still come first, named as ever
    problem(client.post("/v1/recognize", json={"samples": [[1.0]], "objects": ["a"]}), 422)


def test_the_schema_documents_tables(best_service):
    client = best_service[0]
    doc = client.get("/openapi.json").json()
    op = doc["paths"]["/v1/recognize"]["post"]
    params = {p["name"]: p for p in op["parameters"]}
    assert (
        params["objects"]["in"] == "query" and "comma-separated" in params["objects"]["description"]
    )
    assert params["X-Tactile-Objects"]["in"] == "header"
    schemas = doc["components"]["schemas"]
    assert "objects" in schemas["RecognizeRequest"]["properties"]
    assert "objects" in schemas["RecognizeTrialsRequest"]["properties"]
    result = schemas["RecognizeResult"]["properties"]
    for field in ("object", "alone", "margin", "touches"):
        assert len(result[field]["description"]) > 30, field


def test_a_label_beyond_64_bits_is_refused_before_it_is_echoed():
    with pytest.raises(LabelError, match="must fit in 64 bits") as caught:
        check_labels(["a", 2**70], 2)
    assert caught.value.field == "objects[1]"


def test_raw_trials_are_named_as_a_table_from_json_or_hdf5(raw_service, pilot, tmp_path):
    """Held-out pilot trials, labelled with their objects: one answer per object from all
    its trials' fingers, as name_table names them; an HDF5 body takes query labels."""
    client, app = raw_service
    held = pilot[2]
    objects = [held.class_names[y] for y in held.labels]
    trials = list(held.trials)
    r = client.post(
        "/v1/recognize", json={"trials": [trial_json(t) for t in trials], "objects": objects}
    )
    assert r.status_code == 200, r.text
    results = r.json()["results"]
    assert [a["object"] for a in results] == list(dict.fromkeys(objects))
    assert [a["touches"] for a in results] == [objects.count(a["object"]) for a in results]
    rec, kept = served(app)
    class_ids = app.state.service.holder.current.class_ids
    want = expected(rec, trials, objects, kept, class_ids)
    for w in want:  # name_table counts a raw-trial model's rows in trials
        w["touches"] = objects.count(w["object"])
    assert_same_table(results, want)
    path = tmp_path / "trials.h5"
    write_biotac_h5(path, {f"t{i:02d}": t for i, t in enumerate(trials)})
    by_hdf5 = client.post(
        "/v1/recognize",
        content=path.read_bytes(),
        headers={"Content-Type": "application/x-hdf5", "X-Tactile-Objects": ",".join(objects)},
    )
    assert by_hdf5.status_code == 200, by_hdf5.text
    assert by_hdf5.json() == r.json()
    body = problem(
        client.post(
            "/v1/recognize", json={"trials": [trial_json(t) for t in trials[:2]], "objects": ["a"]}
        ),
        422,
        "objects",
    )
    assert "1 labels for 2 trials; give exactly one label per trial" in body["detail"]


def test_an_object_touched_by_a_broken_sensor_abstains_and_takes_no_class(best_service, best_base):
    """Its touches are no evidence: it names no class, and the other objects are named as
    if it were not on the table; outliers=answer names it with the others."""
    client, app, _ = best_service
    data = best_base[1]
    x = table_of(data, 1, range(3))
    zeros = np.zeros_like(x[:1])
    table = np.concatenate([zeros, x])
    objects = ["broken", "a", "b", "c"]
    r = client.post("/v1/recognize", json={"samples": table.tolist(), "objects": objects})
    assert r.status_code == 200, r.text
    broken, *rest = r.json()["results"]
    assert broken["object"] == "broken" and broken["kind"] == "input_outlier"
    assert broken["class_name"] is None and broken["alone"] is None and broken["margin"] is None
    rec, kept = served(app)
    class_ids = app.state.service.holder.current.class_ids
    assert_same_table(rest, expected(rec, x, objects[1:], kept, class_ids))
    guessed = client.post(
        "/v1/recognize?outliers=answer", json={"samples": table.tolist(), "objects": objects}
    ).json()["results"]
    assert guessed[0]["input_outlier"] is True and guessed[0]["alone"] is not None
    assert_same_table(guessed, expected(rec, table, objects, kept, class_ids))


def test_the_client_sends_tables_and_names_them_offline_as_the_service(
    best_service, best_base, tmp_path
):
    from app.client import TactileClient
    from app.testing.harness import free_port

    client, app, _ = best_service
    model_file = tmp_path / "robot" / "model.bundle"
    robot = TactileClient(http=client, model_file=model_file, retries=0, timeout=5)
    robot.sync_model()
    x = table_of(best_base[1], 2)
    labels = [3, "cup", "cup", 3, "lid", "box", "box", "lid"]
    online = robot.recognize(x, objects=labels)
    away = TactileClient(
        f"http://127.0.0.1:{free_port()}", model_file=model_file, retries=0, timeout=2
    )
    offline = away.recognize(x, objects=labels)
    assert online["source"] == "service" and offline["source"] == "offline"
    assert [a["object"] for a in online["results"]] == [3, "cup", "lid", "box"]
    assert offline["model_version"] == online["model_version"]
    assert_same_table(offline["results"], picked(online["results"]))
    np.testing.assert_allclose(
        [a["novelty_score"] for a in offline["results"]],
        [a["novelty_score"] for a in online["results"]],
        rtol=1e-6,
    )
    with pytest.raises(ValueError, match="use one or the other"):
        robot.recognize(x, same_object=True, objects=labels)
    with pytest.raises(LabelError, match="2 labels for 8 samples"):
        away.recognize(x, objects=labels[:2])


def test_held_out_trials_of_known_objects_are_named_as_those_objects(raw_service, pilot):
    """The pilot objects the model knows, touched again: recognised one trial at a time
    (all 12 right), a table of them must name each as itself, not as novel."""
    client, _ = raw_service
    held = pilot[2]
    objects = [held.class_names[y] for y in held.labels]
    body = {"trials": [trial_json(t) for t in held.trials]}
    each = client.post("/v1/recognize", json=body).json()["results"]
    assert sum(a["class_name"] == o for a, o in zip(each, objects, strict=True)) >= 11
    table = client.post("/v1/recognize", json={**body, "objects": objects}).json()["results"]
    named = [(a["object"], a["class_name"]) for a in table]
    assert sum(a["class_name"] == a["object"] for a in table) >= len(table) - 1, named
