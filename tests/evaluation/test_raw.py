"""The raw-trial protocol (``evaluate --dataset biotac:DIR``): trial-disjoint and
held-out-pressure splits, models fitted on training trials only, its summaries, its
report, and the command on the real pilot at tiny size."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from app.cli import main
from app.evaluation import metrics, procedures, raw
from app.evaluation.report import write_report
from app.evaluation.splits import SplitError
from app.framework import registry
from app.methods.best import BestRecognizer
from tests.framework.raw_data import pilot_path, synthetic_biotac


class RecordingBest(BestRecognizer):
    """``best`` that records the trial groups every fit was given."""

    method = "recording-best"
    fitted_on: list[set[str]] = []

    def fit(self, dataset, progress=False):
        RecordingBest.fitted_on.append(set(dataset.groups))
        return super().fit(dataset, progress)


@pytest.fixture()
def recording(monkeypatch):
    RecordingBest.fitted_on = []
    monkeypatch.setitem(registry.METHODS, "recording-best", f"{__name__}:RecordingBest")
    return RecordingBest


@pytest.fixture(scope="module")
def data():
    return synthetic_biotac(n_objects=3, trials_per_object=6)


FAST = {"n_estimators": 20, "tuning_rounds": 1, "featurizer_params": {"n_offsets": 1}}


def test_trial_splits_hold_out_whole_trials_of_every_object(data):
    splits = raw.trial_splits(data, n_splits=4, seed=3, test_trials=2)
    assert len(splits) == 4
    for train, test in splits:
        assert not set(train) & set(test) and len(train) + len(test) == len(data)
        assert np.bincount(data.labels[test]).tolist() == [2, 2, 2]
    assert len({tuple(t) for _, t in splits}) > 1
    again = raw.trial_splits(data, n_splits=4, seed=3, test_trials=2)
    assert all(np.array_equal(a[1], b[1]) for a, b in zip(splits, again, strict=True))
    with pytest.raises(SplitError, match="has 6 trial"):
        raw.trial_splits(data, n_splits=1, seed=0, test_trials=6)


def test_pressure_splits_test_on_one_pressure_and_train_on_the_others(data):
    folds = raw.pressure_splits(data)
    assert sorted(folds) == [100.0, 150.0, 200.0]
    for level, (train, test) in folds.items():
        assert (data.grip_pressure[test] == level).all()
        assert (data.grip_pressure[train] != level).all()
        assert len(train) + len(test) == len(data)
    validation = raw.pressure_validation_splits(data)
    for level, pairs in validation.items():
        assert len(pairs) == 2
        for fit, val in pairs:  # never a trial of the held-out pressure
            assert (data.grip_pressure[np.r_[fit, val]] != level).all()
            assert len(np.unique(data.grip_pressure[fit])) == 1
            assert data.grip_pressure[fit[0]] != data.grip_pressure[val[0]]


def test_pressure_splits_need_a_pressure_for_every_trial(data):
    from dataclasses import replace

    unnamed = replace(data, grip_pressure=np.r_[np.nan, data.grip_pressure[1:]])
    with pytest.raises(SplitError, match="no grip pressure"):
        raw.pressure_splits(unnamed)


def test_mean_interval_is_students_t():
    low, high = metrics.mean_interval([1.0, 2.0, 3.0])
    half = 4.302652729911275 / math.sqrt(3)  # t(0.975, 2) x sd 1 / sqrt(3)
    assert (low, high) == pytest.approx((2 - half, 2 + half))
    assert all(math.isnan(v) for v in metrics.mean_interval([0.5]))
    assert metrics.mean_interval([0.9, 0.9, 0.9]) == pytest.approx((0.9, 0.9))
    # a fraction's interval stays within [0, 1] when asked
    assert metrics.mean_interval([1.0, 1.0, 0.8], bounds=(0.0, 1.0))[1] == 1.0
    assert metrics.mean_interval([1.0, 1.0, 0.8])[1] > 1.0


def test_wilson_interval_of_an_accuracy_on_n_trials():
    # 25 of 25: the centre (1 + z^2/2n) / (1 + z^2/n) and half-width z^2/2n / (1 + z^2/n)
    z2 = 1.959963984540054**2
    low, high = metrics.wilson_interval(1.0, 25)
    assert high == pytest.approx(1.0) and low == pytest.approx(1 / (1 + z2 / 25))
    low, high = metrics.wilson_interval(0.5, 100)
    assert (low + high) / 2 == pytest.approx(0.5) and high - low == pytest.approx(0.1923, abs=1e-3)
    with pytest.raises(ValueError):
        metrics.wilson_interval(0.5, 0)


def test_every_model_is_fitted_on_training_trials_only(data, recording):
    results = raw.evaluate_raw(
        data,
        ["recording-best"],
        n_splits=2,
        seed=1,
        test_trials=2,
        method_params={"recording-best": FAST},
        progress=False,
    )
    entry = results["methods"]["recording-best"]
    assert len(recording.fitted_on) == 2 + 3 * 2
    for split, seen in zip(results["split_definitions"], recording.fitted_on[:2], strict=True):
        assert not set(split["test_trials"]) & seen
        assert len(seen) == len(data) - 6
    pressure_of = dict(zip(data.groups, data.grip_pressure, strict=True))
    levels = [100.0] * 2 + [150.0] * 2 + [200.0] * 2
    for seen, level in zip(recording.fitted_on[2:], levels, strict=True):
        assert level not in {pressure_of[g] for g in seen}
    assert [p["pressure"] for p in entry["pressure"]] == levels
    assert [p["seed"] for p in entry["pressure"]] == [1, 2] * 3
    for figure in ("known_acc", "known_acc_finger", "nd_known_kept", "pressure_100"):
        assert 0.0 <= entry["mean"][figure] <= 1.0
        low, high = entry["ci95"][figure]
        assert low <= entry["mean"][figure] <= high
    accs = [s["known_acc"] for s in entry["splits"]]
    assert entry["mean"]["known_acc"] == pytest.approx(np.mean(accs))
    assert entry["std"]["known_acc"] == pytest.approx(np.std(accs, ddof=1))
    by_repeat = [
        np.mean([p["accuracy"] for p in entry["pressure"] if p["repeat"] == r]) for r in (1, 2)
    ]
    assert entry["mean"]["pressure_mean"] == pytest.approx(np.mean(by_repeat))
    n_trials = int(np.sum(data.grip_pressure == 150.0))
    low, high = metrics.wilson_interval(entry["mean"]["pressure_150"], n_trials)
    assert entry["binomial95"]["pressure_150"] == pytest.approx([low, high])
    assert set(entry["binomial95"]) == {"pressure_100", "pressure_150", "pressure_200"}
    assert np.asarray(entry["confusion"]).sum() == 2 * 6  # test trials of both splits
    assert np.asarray(entry["confusion_pressure"]).sum() == 2 * len(data)


def test_validation_never_measures_on_test_trials(data, recording):
    results = raw.evaluate_raw(
        data,
        ["recording-best"],
        n_splits=2,
        seed=1,
        test_trials=1,
        method_params={"recording-best": FAST},
        progress=False,
        validation=True,
    )
    assert results["validation"] is True
    tests = raw.trial_splits(data, 2, 1, 1)
    entry = results["methods"]["recording-best"]
    fits = recording.fitted_on[:2]
    for (_, test), seen, details in zip(tests, fits, entry["details"], strict=True):
        test_groups = {data.groups[i] for i in test}
        assert not test_groups & seen and not test_groups & set(details["test_trials"])
        assert len(seen) == len(data) - 2 * 3  # test and validation trials out
    assert len(recording.fitted_on) == 2 + 3 * 2 * 2  # two (fit, validation) pairs per pressure


def test_raw_results_get_their_report(data, tmp_path):
    results = raw.evaluate_raw(
        data, ["best"], n_splits=2, method_params={"best": FAST}, progress=False
    )
    files = write_report(results, tmp_path)
    names = {f.name for f in files}
    assert names == {"report.md", "accuracy.png", "confusion_best.png"}
    text = (tmp_path / "report.md").read_text()
    assert "| `known_acc` |" in text and "| `pressure_150` |" in text
    assert "95 % confidence interval" in text and "Wilson 95 % interval" in text
    assert (tmp_path / "accuracy.png").read_bytes()[:4] == b"\x89PNG"


def test_the_evaluate_command_on_the_pilot_at_tiny_size(tmp_path, capsys):
    out = tmp_path / "results.json"
    code = main(
        [
            "evaluate",
            "--dataset",
            f"biotac:{pilot_path()}",
            "--splits",
            "2",
            "--methods",
            "best,paper,extratrees",
            "--param",
            'best.featurizer_params={"n_offsets": 1}',
            "--param",
            "best.n_estimators=30",
            "--param",
            "paper.encoder_epochs=3",
            "--param",
            'paper.featurizer_params={"n_offsets": 1}',
            "--param",
            "extratrees.n_estimators=30",
            "--param",
            'extratrees.featurizer_params={"n_offsets": 1}',
            "--out",
            str(out),
            "--report",
            str(tmp_path / "report"),
            "--no-progress",
        ]
    )
    assert code == 0
    results = json.loads(out.read_text())
    assert results["protocol"] == "raw-trials" and results["pressures"] == [100.0, 150.0, 200.0]
    assert results["config"]["n_trials"] == 74 and results["config"]["n_attributes"] == 0
    for m in ("best", "paper", "extratrees"):
        entry = results["methods"][m]
        assert len(entry["splits"]) == 2 and len(entry["pressure"]) == 3 * 2
        assert set(entry["mean"]) == {
            "known_acc", "known_acc_finger", "nd_known_kept",
            "pressure_100", "pressure_150", "pressure_200", "pressure_mean",
        }  # fmt: skip
    assert results["methods"]["best"]["mean"]["known_acc"] >= 0.8
    # paired differences from the first method, split by split and repeat by repeat
    paired = results["paired"]
    assert paired["reference"] == "best" and list(paired["methods"]) == ["paper", "extratrees"]
    best, paper = results["methods"]["best"], results["methods"]["paper"]
    d = [
        p["known_acc"] - b["known_acc"]
        for p, b in zip(paper["splits"], best["splits"], strict=True)
    ]
    assert paired["methods"]["paper"]["splits"]["known_acc"] == pytest.approx(d)
    d200 = [
        p["accuracy"] - b["accuracy"]
        for p, b in zip(paper["pressure"], best["pressure"], strict=True)
        if p["pressure"] == b["pressure"] == 200.0
    ]
    assert paired["methods"]["paper"]["splits"]["pressure_200"] == pytest.approx(d200)
    assert paired["methods"]["paper"]["mean"]["pressure_200"] == pytest.approx(np.mean(d200))
    printed = capsys.readouterr().out
    assert "known_acc" in printed and "pressure_200" in printed
    assert "paired difference from best" in printed and "paper - best" in printed
    assert (tmp_path / "report" / "accuracy.png").is_file()


def test_procedures_on_raw_trials_give_figures_against_the_phases_used(data, tmp_path):
    results = raw.evaluate_raw(
        data,
        ["best"],
        n_splits=2,
        seed=1,
        test_trials=2,
        method_params={"best": FAST},
        progress=False,
        held_out_pressure=False,
        procedures_measured=True,
        durations={"hold": 16.93},
    )
    assert results["procedures"] == ["tap", "hold", "squeeze"]  # the featurizer's phases
    assert results["durations"] == [0.23, 16.93, 4.2]
    entry = results["methods"]["best"]
    for split in entry["splits"]:
        # every phase: the protocol's own figures, one answer per trial from both fingers
        assert split["procs111_known_acc"] == split["known_acc"]
        assert split["procs111_nd_known_kept"] == split["nd_known_kept"]
        for t in results["procedure_targets"]:
            key = procedures.target_key(t)
            assert 2 <= split[f"{key}_procedures"] <= 3  # two phases at least
            assert 0 < split[f"{key}_time"] <= 1 and 0 <= split[f"{key}_known_acc"] <= 1
    assert set(procedures.procedure_figures_known(3)) <= set(entry["ci95"])
    # the main table leaves them to a section of their own
    assert not any(f.startswith(("procs", "adaptive")) for f in raw.raw_figures(results))
    files = write_report(results, tmp_path)
    text = files[0].read_text()
    assert "## Figures against the procedures used" in text and "| 1 + 3 |" in text
    assert (tmp_path / "procedures.png").stat().st_size > 0


def test_explore_answers_a_trial_from_its_fingers_together(data):
    model = registry.make_method("best", **FAST).fit(data.subset(np.arange(len(data)) % 6 != 0))
    trials = list(data.subset(np.arange(len(data)) % 6 == 0).trials)
    images, index = model.trial_samples(trials)
    used = procedures.explore(model, images, 1.0, index)  # sure only at probability 1
    assert used.shape == (len(trials), 3) and (used.sum(axis=1) >= 2).all()
    answers = model.recognize_batch(
        procedures.masked(images, used[index]), top_k=1, groups=index, target_confidence=1.0
    )
    assert ((answers.top_probability[:, 0] == 1.0) | used.all(axis=1)).all()
    used = procedures.explore(model, images, 1e-9, index)  # sure at once: two phases
    first = model.procedures.index(model.first_procedure)
    assert (used.sum(axis=1) == 2).all() and used[:, first].all()
