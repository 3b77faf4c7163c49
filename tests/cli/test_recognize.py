"""tactile-zsl recognize: a bundle file answers as the model does, from .npy, .json or
stdin; bad input exits 2 with a message that names the problem."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from app.cli import main
from app.framework import bundle
from app.testing.service import trained_base


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    model, dataset = trained_base()
    path = tmp_path_factory.mktemp("model") / "model.bundle"
    bundle.save(model, path)
    return path, model, dataset.samples[::5][:10]


def run(capsys, *argv: str) -> tuple[int, dict | None, str]:
    code = main(["recognize", *argv])
    out, err = capsys.readouterr()
    return code, json.loads(out) if code == 0 else None, err


def test_npy_samples_get_the_models_own_answers(saved, tmp_path, capsys):
    path, model, x = saved
    np.save(tmp_path / "x.npy", x)
    code, printed, _ = run(capsys, "--model", str(path), "--top-k", "2", str(tmp_path / "x.npy"))
    assert code == 0 and printed["method"] == model.method
    expected = model.recognize_batch(x, top_k=2, known_kept=model.operating_point()).records()
    assert [r["class_name"] for r in printed["results"]] == [r["class_name"] for r in expected]
    assert all(len(r["top_k"]) == 2 and "class_id" not in r for r in printed["results"])
    np.testing.assert_allclose(
        [r["novelty_score"] for r in printed["results"]],
        [r["novelty_score"] for r in expected],
        rtol=1e-6,
    )


def test_one_bare_sample_and_json_from_a_file_or_stdin(saved, tmp_path, capsys, monkeypatch):
    path, model, x = saved
    np.save(tmp_path / "one.npy", x[0])
    (tmp_path / "x.json").write_text(json.dumps({"samples": x[:3].tolist()}))
    _, one, _ = run(capsys, "--model", str(path), str(tmp_path / "one.npy"))
    _, from_file, _ = run(capsys, "--model", str(path), str(tmp_path / "x.json"))
    monkeypatch.setattr("sys.stdin", io.StringIO(json.dumps({"samples": x[:3].tolist()})))
    _, from_stdin, _ = run(capsys, "--model", str(path), "-")
    assert len(one["results"]) == 1 and len(from_file["results"]) == 3
    assert from_stdin == from_file
    assert one["results"][0]["class_name"] == from_file["results"][0]["class_name"]


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda d, x: d / "missing.npy", "no samples file at"),
        (lambda d, x: _write(d / "x.csv", "1,2"), "must be a .npy or .json file"),
        (lambda d, x: _write(d / "x.json", "{not json"), "is not JSON"),
        (lambda d, x: _write(d / "x.json", "[1, 2]"), 'must hold an object {"samples": [...]}'),
        (lambda d, x: _write(d / "x.npy", "garbage"), "is not a readable .npy array"),
        (lambda d, x: _save(d / "x.npy", x[:, :3]), "expected samples of shape"),
        (
            lambda d, x: _save(
                d / "x.npy", np.where(np.arange(x.size).reshape(x.shape) == 7, np.nan, x)
            ),
            "is partly missing: cell [0][0][7] is NaN where the procedure's other values are "
            "numbers; send all of its values, or none",
        ),
    ],
)
def test_bad_samples_exit_2_and_say_why(saved, tmp_path, capsys, make, message):
    path, _, x = saved
    code, _, err = run(capsys, "--model", str(path), str(make(tmp_path, x)))
    assert code == 2 and message in err, err


def test_a_missing_or_damaged_model_exits_2(saved, tmp_path, capsys):
    _, _, x = saved
    samples = _save(tmp_path / "x.npy", x)
    code, _, err = run(capsys, "--model", str(tmp_path / "none.bundle"), str(samples))
    assert code == 2 and "no model bundle at" in err
    code, _, err = run(
        capsys, "--model", str(_write(tmp_path / "bad.bundle", "garbage")), str(samples)
    )
    assert code == 2 and "not a readable model bundle" in err
    code, _, err = run(capsys, "--model", str(saved[0]), "--top-k", "0", str(samples))
    assert code == 2 and "--top-k must be at least 1" in err


def _write(path, text: str):
    path.write_text(text)
    return path


def _save(path, array):
    np.save(path, array)
    return path


def test_lines_are_answered_one_by_one_and_a_new_model_file_is_picked_up(saved, tmp_path):
    from app.cli.recognize import answer_lines

    path, model, _ = saved
    robot_file = tmp_path / "robot.bundle"
    bundle.save(model, robot_file)
    _, dataset = trained_base()
    x = dataset.samples[:40]
    vector = np.zeros(len(model.registry.attribute_names), np.float32)
    vector[[0, 3, 5]] = 1
    newer = model.add_novel_classes(["teapot"], vector[None], allow_known_vectors=True)
    assert newer.recognize_batch(x).records() != model.recognize_batch(x).records()  # told apart

    def lines():
        yield json.dumps({"samples": x.tolist()})
        yield "{not json"
        yield json.dumps({"samples": x[:, :3].tolist()})
        yield ""  # blank lines are skipped
        robot_file.write_bytes(b"garbage")  # a damaged replacement: the old model goes on
        yield json.dumps({"samples": x.tolist()})
        bundle.save(newer, robot_file)
        yield json.dumps({"samples": x.tolist()})

    out = io.StringIO()
    assert answer_lines(robot_file, lines(), out, top_k=3) == 0
    answers = [json.loads(line) for line in out.getvalue().splitlines()]
    assert len(answers) == 5
    at_default = {"known_kept": model.operating_point()}  # the service's default
    assert answers[0]["results"] == model.recognize_batch(x, **at_default).records()
    assert (
        "is not JSON" in answers[1]["error"] and "expected samples of shape" in answers[2]["error"]
    )
    assert answers[3]["results"] == model.recognize_batch(x, **at_default).records()
    assert "cannot be read" in answers[3]["warning"]
    assert (
        answers[4]["results"] == newer.recognize_batch(x, **at_default).records()
        and "warning" not in answers[4]
    )


def test_a_lines_process_answers_each_line_as_it_comes(saved):
    import subprocess

    from app.testing.harness import tactile_zsl

    path, model, x = saved
    proc = subprocess.Popen(
        [*tactile_zsl(), "recognize", "--model", str(path), "--lines", "-"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        for samples in (x[:2], x[2:3]):
            proc.stdin.write(json.dumps({"samples": samples.tolist()}) + "\n")
            proc.stdin.flush()
            answer = json.loads(proc.stdout.readline())  # answered before the input ends
            assert [r["class_name"] for r in answer["results"]] == [
                r["class_name"] for r in model.recognize_batch(samples).records()
            ]
        proc.stdin.write("[1]\n")
        proc.stdin.flush()
        assert "must hold an object" in json.loads(proc.stdout.readline())["error"]
        proc.stdin.close()
        assert proc.wait(timeout=60) == 0
    finally:
        proc.kill()
        proc.wait()


def test_lines_need_a_model_that_loads_at_the_start(tmp_path, capsys):
    code, _, err = run(capsys, "--model", str(tmp_path / "none.bundle"), "--lines", "-")
    assert code == 2 and "no model bundle at" in err
