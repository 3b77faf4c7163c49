"""tactile-zsl train on raw BioTac trials writes a raw-trial model; tactile-zsl recognize
answers raw trials with it, one answer per trial, and refuses them with a model of samples."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.cli import main
from app.data.biotac import write_biotac_folder
from app.framework import bundle
from tests.framework.raw_data import synthetic_biotac


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("raw")
    raw = synthetic_biotac(n_objects=3, trials_per_object=6)
    write_biotac_folder(raw, root / "data")
    out = root / "model.bundle"
    code = main(
        [
            "train",
            "--dataset",
            f"biotac:{root / 'data'}",
            "--method",
            "best",
            "--param",
            "n_estimators=30",
            "--param",
            "tuning_rounds=1",
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert code == 0
    return out, raw


def test_train_on_raw_trials_writes_a_model_that_takes_raw_trials(trained):
    path, raw = trained
    model = bundle.load(path)
    assert model.input_kind == "raw_trials" and model.input_shape == (24, 30)
    assert model.registry.known_names == ["obj0", "obj1", "obj2"]
    assert model.metrics["n_train_samples"] == len(raw) * 2


def test_recognize_answers_raw_trials_once_per_trial(trained, tmp_path, capsys):
    path, raw = trained
    request = {"trials": [raw.trials[i].to_dict() for i in (0, 7, 13)]}
    (tmp_path / "trials.json").write_text(json.dumps(request))
    code = main(["recognize", "--model", str(path), str(tmp_path / "trials.json")])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and len(out["results"]) == 3
    assert [r["class_name"] for r in out["results"]] == ["obj0", "obj1", "obj2"]
    model = bundle.load(path)
    trials = [raw.trials[i] for i in (0, 7, 13)]
    expected = model.recognize_trials(trials, known_kept=model.operating_point()).records()
    assert out["results"] == expected


def test_recognize_refuses_samples_for_a_raw_trial_model_and_trials_for_a_samples_model(
    trained, tmp_path, capsys
):
    path, raw = trained
    np.save(tmp_path / "x.npy", np.zeros((2, 32, 30), np.float32))
    assert main(["recognize", "--model", str(path), str(tmp_path / "x.npy")]) == 2
    assert "fitted on raw BioTac trials" in capsys.readouterr().err
    samples_model = tmp_path / "samples.bundle"
    assert (
        main(
            [
                "train",
                "--dataset",
                "simulated:6",
                "--method",
                "best",
                "--param",
                "n_estimators=20",
                "--param",
                "tuning_rounds=1",
                "--out",
                str(samples_model),
                "--quiet",
            ]
        )
        == 0
    )
    capsys.readouterr()
    (tmp_path / "trials.json").write_text(json.dumps({"trials": [raw.trials[0].to_dict()]}))
    assert main(["recognize", "--model", str(samples_model), str(tmp_path / "trials.json")]) == 2
    assert "takes fixed-shape samples" in capsys.readouterr().err
