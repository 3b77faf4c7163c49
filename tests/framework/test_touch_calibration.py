"""Calibration per kind of answer: the curves of answers fusing k touches, measured at fit
on held-out known trials (``touch_curves``), are stored with the novelty tuning and its
bundle, and an answer fusing k touches is routed by the threshold read off the curve of k
(or the largest k measured below), and says which."""

from __future__ import annotations

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.framework import bundle
from app.framework.novelty import MIN_GROUPS, touch_curves, tune_threshold
from app.framework.registry import make_method
from app.framework.state import NoveltyTuning
from tests.kept_share import curve_resolution


def held_out(n_objects: int, trials: int, seed: int = 0):
    """Scores of ``trials`` held-out trials of each object: an object's own level plus
    noise, so that fusing touches averages the noise away but not the level."""
    rng = np.random.default_rng(seed)
    level = rng.normal(0, 1, n_objects)
    objects = np.repeat(np.arange(n_objects), trials)
    scores = level[objects] + rng.normal(0, 1, len(objects))
    return scores, np.c_[objects, np.tile(np.arange(trials), n_objects)]


def test_fused_curves_keep_their_stated_share_of_fused_answers():
    scores, ids = held_out(60, 4)
    curves = touch_curves(scores, ids, max_touches=5)
    assert sorted(curves) == [1, 2, 3, 4]  # no object has 5 trials
    by_object = scores.reshape(60, 4)
    for k in (2, 3, 4):
        thresholds, kept = curves[k]
        assert np.all(np.diff(thresholds) > 0) and np.all(np.diff(kept) >= 0)
        at = np.searchsorted(kept, 0.9)
        t = thresholds[at]
        # every k-subset of each object's trials is a group, the touches the curve was
        # measured on: the share kept is the curve's, the stated one to within its step
        fused = [np.mean(by_object[o, list(s)]) for o in range(60) for s in _subsets(4, k)]
        assert np.mean(np.array(fused) <= t) == pytest.approx(kept[at])
        assert 0 <= kept[at] - 0.9 <= curve_resolution(kept), (k, kept[at])
    # fused scores vary less: the threshold keeping 0.9 of them lies lower
    single = np.quantile(scores, 0.9)
    assert curves[3][0][np.searchsorted(curves[3][1], 0.9)] < single


def _subsets(n: int, k: int) -> list[tuple[int, ...]]:
    import itertools

    return list(itertools.combinations(range(n), k))


def test_too_few_groups_measure_no_curve():
    scores, ids = held_out(MIN_GROUPS - 1, 2)
    assert sorted(touch_curves(scores, ids)) == [1]  # one group of 2 an object: too few
    scores, ids = held_out(3, 2)
    assert touch_curves(scores, ids) == {}


def test_the_tuning_reads_the_curve_of_as_many_touches_and_keeps_it_in_its_dict():
    scores, ids = held_out(60, 3)
    novel = np.random.default_rng(1).normal(3, 1, 50)
    tuning = tune_threshold(scores, novel, known_trials=ids)
    assert sorted(tuning.touches) == [1, 2, 3]
    assert tuning.curve_for(0) == 0 and tuning.curve_for(2) == 2 and tuning.curve_for(9) == 3
    assert tuning.threshold_keeping_touches(0.9, 0) == (tuning.threshold_keeping(0.9), 0)
    t3, k = tuning.threshold_keeping_touches(0.9, 7)
    assert k == 3 and t3 < tuning.threshold_keeping(0.9)
    back = NoveltyTuning.from_dict(tuning.to_dict())
    assert back.threshold_keeping_touches(0.9, 3) == (t3, 3)
    # a tuning stored before the curves reads the single curve for every answer
    old = {key: v for key, v in tuning.to_dict().items() if key != "touches"}
    assert NoveltyTuning.from_dict(old).threshold_keeping_touches(0.9, 3)[1] == 0


@pytest.fixture(scope="module", params=["best", "prototypes"])
def best_model(request):
    """Each method that measures fused curves: ``best`` on its held-out probe trials,
    ``prototypes`` on its training touches scored without their own trial."""
    data = simulate_dataset(n_objects=30, trials_per_object=8, seed=2)
    params = {"n_estimators": 40, "tuning_rounds": 5} if request.param == "best" else {}
    return make_method(request.param, seed=0, **params).fit(data), data


def test_fused_answers_are_routed_by_the_curve_of_their_touches(best_model, tmp_path):
    model, data = best_model
    tuning = model.novelty_tuning
    assert 3 in tuning.touches
    x = data.samples[:6]
    groups = np.array([0, 0, 0, 1, 1, 2])
    batch = model.recognize_batch(x, groups=groups, known_kept=0.9)
    assert batch.calibrated_touches.tolist() == [3, 2, 1]
    expected = [tuning.threshold_keeping_touches(0.9, k)[0] for k in (3, 2)]
    assert batch.novelty_threshold.tolist() == [*expected, tuning.threshold_keeping(0.9)]
    assert batch.is_novel.tolist() == (batch.novelty_score > batch.novelty_threshold).tolist()
    records = batch.records()
    assert [r["calibrated_touches"] for r in records] == [3, 2, 1]
    # single samples read the single curve; the model's own threshold reads none
    assert model.recognize_batch(x, known_kept=0.9).calibrated_touches.tolist() == [1] * 6
    assert model.recognize_batch(x, groups=groups).calibrated_touches is None
    # said explicitly: 3 touches in one group, whatever its samples
    told = model.recognize_batch(x[:2], groups=[0, 0], known_kept=0.9, touches=[3])
    assert told.calibrated_touches.tolist() == [3]
    with pytest.raises(ValueError, match="touches must give each of the 1 groups"):
        model.recognize_batch(x[:2], groups=[0, 0], known_kept=0.9, touches=[0])
    # the bundle keeps the curves
    bundle.save(model, tmp_path / "m.bundle")
    loaded = bundle.load(tmp_path / "m.bundle")
    assert loaded.recognize_batch(x, groups=groups, known_kept=0.9).records() == records
