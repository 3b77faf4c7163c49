"""``prototypes`` measures the curves of answers fusing k touches at fit (its threshold's
probe holds out one trial a class, too few to fuse), so a fused answer states the share it
keeps as ``best``'s does: the curves exist and rise (tests/framework/test_touch_calibration.py
routes fused answers by them and saves them in bundles); on PHAC-2's development splits,
three fused touches keep about the stated share where the single touches' curve kept more."""

from __future__ import annotations

import numpy as np
import pytest

from app.data.phac2 import load_phac2
from app.data.simulator import simulate_dataset
from app.evaluation.protocol import split_method_seed
from app.evaluation.splits import make_zsl_splits
from app.framework.registry import make_method
from bench.touch_calibration import one_split


@pytest.fixture(scope="module")
def fitted():
    data = simulate_dataset(n_objects=30, trials_per_object=8, seed=2)
    return make_method("prototypes", seed=0).fit(data), data


def test_fused_curves_are_measured_and_rise(fitted):
    model, _ = fitted
    tuning = model.novelty_tuning
    assert sorted(tuning.touches) == [1, 2, 3, 4, 5]
    for thresholds, kept in tuning.touches.values():
        assert np.all(np.diff(thresholds) >= 0) and np.all(np.diff(kept) >= 0)
        assert kept[-1] == 1.0
    # mapped onto the probe's held-out curve: within its range of thresholds
    low, high = tuning.thresholds[0], tuning.thresholds[-1]
    assert all(low <= t.min() and t.max() <= high for t, _ in tuning.touches.values())


def test_three_touches_keep_about_the_stated_share_on_phac2(phac2_path):
    """Three development splits (seed 7; the reported figures are seed 1000's): fused
    answers of three known touches, routed by their own curve, keep nearer 0.90 than by the
    single touches' curve, which keeps more because a mean of touches varies less."""
    dataset = load_phac2(phac2_path)
    splits = make_zsl_splits(dataset, 6, 3, 7, test_trials=3)
    before, after, groups = [], [], 0
    for split in splits:
        seed = split_method_seed(7, split.index)
        figures = one_split(dataset, split, "prototypes", seed, 0.9, [3])["figures"]
        (known,) = (f for f in figures if f["objects"] == "known")
        before.append(known["before"])
        after.append(known["after"])
        groups += known["groups"]
        assert known["calibrated_touches"] == 3
    kept_before, kept_after = np.mean(before), np.mean(after)
    assert abs(kept_after - 0.9) < abs(kept_before - 0.9)
    # a binomial interval of the groups measured (3 sigma), the curve's own resolution aside
    assert abs(kept_after - 0.9) <= 3 * np.sqrt(0.9 * 0.1 / groups) + 0.02
