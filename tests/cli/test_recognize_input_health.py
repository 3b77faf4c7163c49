"""tactile-zsl recognize prints each answer's input health, as the service answers it."""

from __future__ import annotations

import json

import numpy as np

from app.cli import main
from app.framework import bundle
from app.testing.service import trained_base


def test_the_answers_carry_input_outlier_and_its_score(tmp_path, capsys):
    model, dataset = trained_base()
    path = tmp_path / "model.bundle"
    bundle.save(model, path)
    sound = dataset.samples[::7][:2]
    x = np.concatenate([sound, np.zeros_like(sound[:1]), sound[:1] * 1e6])
    np.save(tmp_path / "x.npy", x)
    assert main(["recognize", "--model", str(path), str(tmp_path / "x.npy")]) == 0
    printed = json.loads(capsys.readouterr().out)["results"]
    assert [r["input_outlier"] for r in printed] == [False, False, True, True]
    # a broken sensor's answer names no object
    assert [r["kind"] == "input_outlier" and r["class_name"] is None for r in printed] == [
        False,
        False,
        True,
        True,
    ]
    expected = model.recognize_batch(x).input_outlier_score
    np.testing.assert_allclose([r["input_outlier_score"] for r in printed], expected, rtol=1e-6)
    # one request per line, as a robot streams them
    lines = tmp_path / "lines.jsonl"
    lines.write_text(json.dumps({"samples": np.zeros_like(sound[:1]).tolist()}) + "\n")
    assert main(["recognize", "--model", str(path), "--lines", str(lines)]) == 0
    (answer,) = json.loads(capsys.readouterr().out)["results"]
    assert answer["input_outlier"] is True and answer["input_outlier_score"] > 2
    assert answer["kind"] == "input_outlier" and answer["class_name"] is None
