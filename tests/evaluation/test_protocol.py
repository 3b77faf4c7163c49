"""The protocol against an oracle recognizer whose figures are known exactly, and the
results.json layout; also checks that no test data reaches training or enrolment."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.evaluation.protocol import FIGURES, evaluate

from .conftest import OracleRecognizer, _key

N_NOVEL = 3


def test_oracle_figures_are_exact(oracle):
    ds = oracle
    res = evaluate(
        ds, ["oracle"], n_novel=N_NOVEL, n_splits=4, seed=4, test_trials=1, progress=False
    )
    entry = res["methods"]["oracle"]
    assert len(entry["splits"]) == 4
    # a novel object with a known twin (same attribute vector) is enrolled and measured
    assert any(set(s["novel_objects"]) & {0, 1, 2, 3} for s in entry["splits"])
    for s in entry["splits"]:
        for f in (
            "known_acc",
            "zsl",
            "osl",
            "nd_novel_detected",
            "nd_auroc",
            "gzsl_seen",
            "gzsl_unseen",
            "gzsl_h",
        ):
            assert s[f] == 1.0, f
        assert s["nd_known_kept"] == 0.9 and s["nd_val_novel"] == 0.7  # taken from the tuning
        assert s["zsl_wrong"] == pytest.approx(1 / N_NOVEL)  # balanced test set, one class answered
        assert s["zsl_same"] == s["zsl"]
    assert entry["mean"]["zsl_wrong"] == pytest.approx(1 / N_NOVEL)
    # per-split confusion matrices: diagonal for zsl, one column for the wrong variant
    d = entry["details"][0]
    assert np.array_equal(np.array(d["confusion_zsl"]), np.diag(np.diag(d["confusion_zsl"])))
    assert (np.array(d["confusion_zsl_wrong"])[:, 1:] == 0).all()
    assert d["novelty_tuning"]["threshold"] == 0.5


def test_no_test_data_reaches_training_and_one_shots_are_right(oracle):
    ds = oracle
    res = evaluate(
        ds, ["oracle"], n_novel=N_NOVEL, n_splits=2, seed=4, test_trials=1, progress=False
    )
    novel_names = {n for s in res["methods"]["oracle"]["splits"] for n in s["novel_names"]}
    from app.evaluation.splits import make_zsl_splits

    splits = make_zsl_splits(ds, N_NOVEL, 2, seed=4, test_trials=1)
    assert len(OracleRecognizer.seen_training) == len(splits)
    for trained, split in zip(OracleRecognizer.seen_training, splits, strict=True):
        assert trained == {_key(x) for x in ds.samples[split.known_train_idx]}
        for idx in (split.known_test_idx, split.novel_test_idx, split.one_shot_idx):
            assert not trained & {_key(x) for x in ds.samples[idx]}
    # every one-shot sample was enrolled under its own class, and is not a test sample
    shots = {_key(x) for split in splits for x in ds.samples[split.one_shot_idx]}
    assert {key for _, key in OracleRecognizer.one_shots} == shots
    for name, key in OracleRecognizer.one_shots:
        assert OracleRecognizer.truth[key] == name and name in novel_names


def test_results_layout_and_json(oracle, tmp_path):
    res = evaluate(
        oracle,
        ["oracle"],
        n_novel=N_NOVEL,
        n_splits=2,
        seed=0,
        test_trials=1,
        progress=False,
        dataset_label="simulated:16",
    )
    text = json.dumps(res)  # plain JSON, no NaN
    back = json.loads(text)
    assert back["dataset"] == "simulated:16" and back["novel"] == N_NOVEL
    assert back["seed"] == 0 and back["splits"] == 2
    entry = back["methods"]["oracle"]
    assert set(entry) >= {"splits", "mean", "elapsed_s"}
    for s in entry["splits"]:
        assert len(s["novel_objects"]) == N_NOVEL and len(s["novel_names"]) == N_NOVEL
        for f in FIGURES:
            assert 0.0 <= s[f] <= 1.0
    for f in FIGURES:
        assert entry["mean"][f] == pytest.approx(np.mean([s[f] for s in entry["splits"]]))


def test_unknown_method_fails_before_any_work(oracle):
    with pytest.raises(ValueError, match="unknown method"):
        evaluate(oracle, ["oracle", "no-such-method"], n_novel=2, n_splits=1, progress=False)


@pytest.mark.parametrize("method", ["dap", "eszsl", "extratrees"])
def test_seed_reaches_methods_that_take_one(method):
    from app.evaluation.protocol import make_recognizer

    assert make_recognizer(method, None, 7).seed == 7
    assert make_recognizer(method, {"seed": 3}, 7).seed == 3  # explicit parameters win
