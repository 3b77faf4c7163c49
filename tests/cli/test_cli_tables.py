"""tactile-zsl recognize --objects: a table of objects named offline, from the service's own
model file, with the answers POST /v1/recognize gives; bad labels exit 2 and say why."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from app.cli import main
from tests import service_fixtures

# a service of method best on the simulator, as the API tests run it
best_base, best_service = service_fixtures.best_base, service_fixtures.best_service


def without_ids(value):
    """An HTTP answer without the store's class ids, which a model file does not hold."""
    if isinstance(value, dict):
        return {k: without_ids(v) for k, v in value.items() if k != "class_id"}
    if isinstance(value, list):
        return [without_ids(v) for v in value]
    return value


@pytest.fixture
def table(best_service, best_base, tmp_path):
    """(HTTP client, the served model's file, samples of a table, their labels)."""
    client = best_service[0]
    r = client.get("/v1/models/active/bundle")
    assert r.status_code == 200
    model_file = tmp_path / "model.bundle"
    model_file.write_bytes(r.content)
    data = best_base[1]
    x = np.concatenate([data.samples[data.labels == k][:2] for k in range(5)])
    labels = ["a", "b", "b", "c", "a", "c", "d", "d", "e", "e"]
    return client, model_file, x, labels


def run(capsys, *argv: str) -> tuple[int, dict | None, str]:
    code = main(["recognize", *argv])
    out, err = capsys.readouterr()
    return code, json.loads(out) if code == 0 else None, err


def test_offline_tables_are_the_services(table, tmp_path, capsys, monkeypatch):
    client, model_file, x, labels = table
    online = client.post("/v1/recognize", json={"samples": x.tolist(), "objects": labels})
    assert online.status_code == 200, online.text
    np.save(tmp_path / "x.npy", x)
    code, printed, err = run(
        capsys, "--model", str(model_file), "--objects", ",".join(labels), str(tmp_path / "x.npy")
    )
    assert code == 0, err
    assert printed["results"] == without_ids(online.json()["results"])
    assert [r["object"] for r in printed["results"]] == ["a", "b", "c", "d", "e"]
    # the labels in the JSON request, as the API takes them, from a file or stdin
    request = json.dumps({"samples": x.tolist(), "objects": labels})
    (tmp_path / "x.json").write_text(request)
    _, from_file, _ = run(capsys, "--model", str(model_file), str(tmp_path / "x.json"))
    monkeypatch.setattr("sys.stdin", io.StringIO(request))
    _, from_stdin, _ = run(capsys, "--model", str(model_file), "--objects", ",".join(labels), "-")
    assert from_file == from_stdin == printed


def test_lines_answer_tables_and_name_bad_labels(table, capsys):
    from app.cli.recognize import answer_lines

    client, model_file, x, labels = table
    online = client.post("/v1/recognize", json={"samples": x.tolist(), "objects": labels}).json()
    lines = [
        json.dumps({"samples": x.tolist(), "objects": labels}),
        json.dumps({"samples": x.tolist(), "objects": labels[:3]}),
        json.dumps({"samples": x[:1].tolist()}),
    ]
    out = io.StringIO()
    assert answer_lines(model_file, lines, out, top_k=3) == 0
    first, bad, plain = (json.loads(line) for line in out.getvalue().splitlines())
    assert first["results"] == without_ids(online["results"])
    assert "3 labels for 10 samples" in bad["error"]
    assert "object" not in plain["results"][0]


@pytest.mark.parametrize(
    "objects, message",
    [
        ("", "no labels given; give one label per sample (10 samples)"),
        ("a,b", "2 labels for 10 samples"),
        ("a,,b,c,d,e,f,g,h,i", "objects[1]: the label is empty"),
    ],
)
def test_bad_labels_exit_2_and_say_why(table, tmp_path, capsys, objects, message):
    _, model_file, x, _ = table
    np.save(tmp_path / "x.npy", x)
    code, _, err = run(
        capsys, "--model", str(model_file), "--objects", objects, str(tmp_path / "x.npy")
    )
    assert code == 2 and message in err, err


def test_labels_given_twice_must_agree(table, tmp_path, capsys):
    _, model_file, x, labels = table
    (tmp_path / "x.json").write_text(json.dumps({"samples": x.tolist(), "objects": labels}))
    code, _, err = run(
        capsys, "--model", str(model_file), "--objects", "a" * 10, str(tmp_path / "x.json")
    )
    assert code == 2 and "give them once" in err, err
    code, _, err = run(
        capsys, "--model", str(model_file), "--lines", "--objects", "a", str(tmp_path / "x.json")
    )
    assert code == 2 and "--lines" in err, err
